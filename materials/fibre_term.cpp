#include "materials/fibre_term.hpp"

#include <cmath>

#include "materials/ad_stress.hpp"

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
  if (request & kEnergy) {
    const double th = in.q[1], ph = in.q[2];
    const Eigen::Vector3d a(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th));
    const double x = (in.F * a).squaredNorm() - 1;
    out.energy = 0.5 * in.q[0] * x * x;
  }
  ad_stress_response<3>(in, request, out, [](const auto& F, const auto& q) {
    using M = std::decay_t<decltype(F)>;
    using S = typename M::Scalar;
    using std::cos;
    using std::sin;
    Eigen::Matrix<S, 3, 1> a;
    a << sin(q[1]) * cos(q[2]), sin(q[1]) * sin(q[2]), cos(q[1]);
    const Eigen::Matrix<S, 3, 1> Fa = F * a;
    return M((S(2) * q[0] * (Fa.squaredNorm() - S(1))) * Fa * a.transpose());
  });
  return true;
}

}  // namespace kelvin
