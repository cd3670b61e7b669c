#include "materials/corotational.hpp"

#include "materials/svd_utils.hpp"

namespace kelvin {

const std::vector<ParamInfo>& Corotational::params() const {
  static const std::vector<ParamInfo> p = {
      {"lambda", "Pa", "first Lamé parameter", 1e4, 0, 1e300, true},
      {"mu", "Pa", "shear modulus (second Lamé parameter)", 1e4, 0, 1e300, true},
  };
  return p;
}

bool Corotational::evaluate(const MaterialPoint& in, unsigned request,
                            MaterialResponse& out) const {
  const double lambda = in.q[0], mu = in.q[1];
  const SignedSvd svd = signed_svd(in.F);
  const Eigen::Vector3d e = svd.sigma.array() - 1.0;  // principal values of S − I
  const double tr = e.sum();
  const Eigen::Vector3d p = 2 * mu * e + Eigen::Vector3d::Constant(lambda * tr);

  if (request & kEnergy) out.energy = mu * e.squaredNorm() + 0.5 * lambda * tr * tr;
  if (request & kStress) out.P = principal_stress(svd, p);
  if (request & kTangent) {
    const Mat3 H = 2 * mu * Mat3::Identity() + lambda * Mat3::Ones();
    out.dPdF = principal_tangent(svd, p, H, Eigen::Vector3d::Constant(2 * mu));
    if (!out.dPdF.allFinite()) return false;
  }
  if (request & kRateTangent) out.dPdFdot.setZero();
  if (request & kParamDerivative) {
    out.dPdq.resize(9, 2);
    Eigen::Map<Mat3>(out.dPdq.col(0).data()) = principal_stress(svd, Eigen::Vector3d::Constant(tr));
    Eigen::Map<Mat3>(out.dPdq.col(1).data()) = principal_stress(svd, 2 * e);
  }
  return true;
}

}  // namespace kelvin
