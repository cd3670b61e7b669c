#include "materials/stiffening.hpp"

#include <Eigen/LU>
#include <cmath>

#include "materials/ad_stress.hpp"

namespace kelvin {

const std::vector<ParamInfo>& Stiffening::params() const {
  static const std::vector<ParamInfo> p = {
      {"c2", "Pa", "stiffening coefficient of (I1 - 3 - 2 ln J)^2", 0.0, 0, 1e300, false},
  };
  return p;
}

bool Stiffening::evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const {
  const double J = in.F.determinant();
  if (!(J > 0)) return false;
  if (request & kEnergy) {
    const double a = in.F.squaredNorm() - 3 - 2 * std::log(J);
    out.energy = in.q[0] * a * a;
  }
  ad_stress_response<1>(in, request, out, [](const auto& F, const auto& q) {
    using M = std::decay_t<decltype(F)>;
    using S = typename M::Scalar;
    using std::log;
    const S a = F.squaredNorm() - S(3) - S(2) * log(F.determinant());
    return M((S(4) * q[0] * a) * (F - M(F.inverse().transpose())));
  });
  return true;
}

}  // namespace kelvin
