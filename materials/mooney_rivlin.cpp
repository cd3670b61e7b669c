#include "materials/mooney_rivlin.hpp"

#include <Eigen/LU>
#include <cmath>

#include "materials/ad_stress.hpp"

namespace kelvin {

const std::vector<ParamInfo>& MooneyRivlin::params() const {
  // Defaults: μ = 2 (C10 + C01) = 1e4 Pa and λ = κ − 2μ/3 = 1e4 Pa, i.e. the same
  // small-strain response as the neo-hookean defaults.
  static const std::vector<ParamInfo> p = {
      {"c10", "Pa", "first Mooney–Rivlin constant (Ī1 term)", 3500, 0, 1e300, false},
      {"c01", "Pa", "second Mooney–Rivlin constant (Ī2 term); μ = 2 (c10 + c01) must be > 0", 1500,
       -1e300, 1e300, false},
      {"kappa", "Pa", "bulk modulus (λ = kappa − 2μ/3)", 1e4 + 2e4 / 3, 0, 1e300, true},
  };
  return p;
}

bool MooneyRivlin::evaluate(const MaterialPoint& in, unsigned request,
                            MaterialResponse& out) const {
  const double J = in.F.determinant();
  if (!(J > 0)) return false;
  if (request & kEnergy) {
    const Mat3 C = in.F.transpose() * in.F;
    const double I1 = C.trace(), I2 = 0.5 * (I1 * I1 - C.squaredNorm());
    const double Jm23 = std::pow(J, -2.0 / 3.0);
    out.energy = in.q[0] * (Jm23 * I1 - 3) + in.q[1] * (Jm23 * Jm23 * I2 - 3) +
                 0.5 * in.q[2] * (J - 1) * (J - 1);
  }
  ad_stress_response<3>(in, request, out, [](const auto& F, const auto& q) {
    using M = std::decay_t<decltype(F)>;
    using S = typename M::Scalar;
    using std::exp;
    using std::log;
    const M C = F.transpose() * F;
    const S I1 = C.trace();
    const S I2 = S(0.5) * (I1 * I1 - C.squaredNorm());
    const S Jd = F.determinant();
    const M G = F.inverse().transpose();
    // J^(−2/3) through exp/log: AutoDiffScalar has no pow with a scalar exponent.
    const S Jm23 = exp(S(-2.0 / 3.0) * log(Jd));
    const S Jm43 = Jm23 * Jm23;
    const M dI1 = Jm23 * (S(2) * F - (S(2.0 / 3.0) * I1) * G);
    const M dI2 = Jm43 * (S(2) * (I1 * F - F * C) - (S(4.0 / 3.0) * I2) * G);
    return M(q[0] * dI1 + q[1] * dI2 + (q[2] * (Jd - S(1)) * Jd) * G);
  });
  return true;
}

}  // namespace kelvin
