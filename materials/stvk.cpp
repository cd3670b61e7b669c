#include "materials/stvk.hpp"

#include "materials/ad_stress.hpp"

namespace kelvin {

const std::vector<ParamInfo>& StVenantKirchhoff::params() const {
  static const std::vector<ParamInfo> p = {
      {"lambda", "Pa", "first Lamé parameter", 1e4, 0, 1e300, true},
      {"mu", "Pa", "shear modulus (second Lamé parameter)", 1e4, 0, 1e300, true},
  };
  return p;
}

bool StVenantKirchhoff::evaluate(const MaterialPoint& in, unsigned request,
                                 MaterialResponse& out) const {
  if (request & kEnergy) {
    const Mat3 E = 0.5 * (in.F.transpose() * in.F - Mat3::Identity());
    out.energy = in.q[1] * E.squaredNorm() + 0.5 * in.q[0] * E.trace() * E.trace();
  }
  ad_stress_response<2>(in, request, out, [](const auto& F, const auto& q) {
    using M = std::decay_t<decltype(F)>;
    using S = typename M::Scalar;
    const M E = S(0.5) * (F.transpose() * F - M::Identity());
    const M Sk = S(2) * q[1] * E + (q[0] * E.trace()) * M::Identity();
    return M(F * Sk);
  });
  return true;
}

}  // namespace kelvin
