#include "materials/fibre_term.hpp"

#include <cmath>

namespace kelvin {

const std::vector<ParamInfo>& FibreTerm::params() const {
  static const std::vector<ParamInfo> p = {
      {"k", "Pa", "fibre stiffness of (I4 - 1)^2 / 2", 0.0, 0, 1e300, false},
      {"theta", "rad", "fibre direction: angle from the z axis", 0.0, -1e300, 1e300, false},
      {"phi", "rad", "fibre direction: angle about the z axis from x", 0.0, -1e300, 1e300, false},
  };
  return p;
}

bool FibreTerm::evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const {
  const double k = in.q[0], th = in.q[1], ph = in.q[2];
  if (k == 0 && !(request & kParamDerivative)) {
    // A fibre screened at k = 0 loads nothing: zero only what was asked for (many
    // such terms are evaluated per element and step).
    out.energy = 0;
    out.P.setZero();
    if (request & kTangent) out.dPdF.setZero();
    if (request & kRateTangent) out.dPdFdot.setZero();
    return true;
  }
  const Eigen::Vector3d a(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th));
  const Eigen::Vector3d f = in.F * a;
  const double x = f.squaredNorm() - 1;  // I₄ − 1
  if (request & kEnergy) out.energy = 0.5 * k * x * x;
  if (request & kStress) out.P = 2 * k * x * f * a.transpose();
  if (request & kRateTangent) out.dPdFdot.setZero();
  if (request & kTangent) {
    // ∂P_ij/∂F_cd = 2k a_j a_d (2 f_i f_c + x δ_ic), columns c + 3d.
    const Mat3 B = 2 * f * f.transpose() + x * Mat3::Identity();
    for (int d = 0; d < 3; ++d)
      for (int j = 0; j < 3; ++j) out.dPdF.block<3, 3>(3 * j, 3 * d) = (2 * k * a[j] * a[d]) * B;
  }
  if (request & kParamDerivative) {
    out.dPdq.resize(9, 3);
    const Mat3 dk = 2 * x * f * a.transpose();
    out.dPdq.col(0) = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(dk.data());
    // Along a change da of the direction: dP = 2k (dx f aᵀ + x F da aᵀ + x f daᵀ).
    const Eigen::Vector3d a_th(std::cos(th) * std::cos(ph), std::cos(th) * std::sin(ph),
                               -std::sin(th));
    const Eigen::Vector3d a_ph(-std::sin(th) * std::sin(ph), std::sin(th) * std::cos(ph), 0);
    int col = 1;
    for (const Eigen::Vector3d& da : {a_th, a_ph}) {
      const Eigen::Vector3d df = in.F * da;
      const Mat3 dP =
          2 * k *
          (2 * f.dot(df) * f * a.transpose() + x * df * a.transpose() + x * f * da.transpose());
      out.dPdq.col(col++) = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(dP.data());
    }
  }
  return std::isfinite(x) && std::isfinite(k);
}

}  // namespace kelvin
