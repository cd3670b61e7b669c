#include "materials/strain_damping.hpp"

#include <Eigen/SVD>

#include "materials/power_law.hpp"

namespace kelvin {

const std::vector<ParamInfo>& StrainDamping::params() const {
  static const std::vector<ParamInfo> p = {
      // 0 is admissible: as a correction added to another viscous term it starts at 0.
      {"d0", "Pa s", "viscosity at rest (σ_max = 1)", 1.0, 0, 1e300, false},
      {"d1", "Pa s", "linear growth of the viscosity with σ_max − 1", 0.0, -1e300, 1e300, false},
      {"d2", "Pa s", "quadratic growth of the viscosity with σ_max − 1", 0.0, -1e300, 1e300, false},
  };
  return p;
}

bool StrainDamping::evaluate(const MaterialPoint& in, unsigned request,
                             MaterialResponse& out) const {
  // The unit-viscosity Newtonian response, scaled: reusing the model keeps both
  // definitions (and their at-rest convention) identical.
  static const NewtonianViscosity newtonian;
  const double one = 1.0;
  MaterialPoint unit = in;
  unit.q = &one;
  MaterialResponse n;
  const bool need_P = request & (kStress | kTangent | kParamDerivative);
  const unsigned nreq = (need_P ? kStress : 0u) | (request & (kTangent | kRateTangent));
  if (!newtonian.evaluate(unit, nreq, n)) return false;

  const double d0 = in.q[0], d1 = in.q[1], d2 = in.q[2];
  Eigen::JacobiSVD<Mat3> svd(in.F,
                             (request & kTangent) ? Eigen::ComputeFullU | Eigen::ComputeFullV : 0);
  const double e = svd.singularValues()[0] - 1;
  const double nu = d0 + d1 * e + d2 * e * e;

  if (request & kEnergy) out.energy = 0;
  if (request & kStress) out.P = nu * n.P;
  if (request & kTangent) {
    const Mat3 dsigma = svd.matrixU().col(0) * svd.matrixV().col(0).transpose();
    const double dnu = d1 + 2 * d2 * e;
    out.dPdF = nu * n.dPdF;
    out.dPdF.noalias() += dnu * Eigen::Map<const Eigen::Matrix<double, 9, 1>>(n.P.data()) *
                          Eigen::Map<const Eigen::Matrix<double, 1, 9>>(dsigma.data());
  }
  if (request & kRateTangent) out.dPdFdot = nu * n.dPdFdot;
  if (request & kParamDerivative) {
    out.dPdq.resize(9, 3);
    const Eigen::Map<const Eigen::Matrix<double, 9, 1>> pn(n.P.data());
    out.dPdq.col(0) = pn;
    out.dPdq.col(1) = e * pn;
    out.dPdq.col(2) = e * e * pn;
  }
  return true;
}

}  // namespace kelvin
