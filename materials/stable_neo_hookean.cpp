#include "materials/stable_neo_hookean.hpp"

#include <Eigen/LU>
#include <cmath>

#include "materials/ad_stress.hpp"

namespace kelvin {
namespace {

template <class S>
Eigen::Matrix<S, 3, 3> snh_stress(const Eigen::Matrix<S, 3, 3>& F,
                                  const Eigen::Matrix<S, 2, 1>& q) {
  const S mu_p = S(4.0 / 3.0) * q[1];
  const S lambda_p = q[0] + S(5.0 / 6.0) * q[1];
  const S alpha = S(1) + S(0.75) * mu_p / lambda_p;
  const S Ic = F.squaredNorm();
  const S J = F.determinant();
  const S shear = mu_p * (S(1) - S(1) / (Ic + S(1)));
  const S vol = lambda_p * (J - alpha);
  return shear * F + vol * cofactor<S>(F);
}

}  // namespace

const std::vector<ParamInfo>& StableNeoHookean::params() const {
  static const std::vector<ParamInfo> p = {
      {"lambda", "Pa", "first Lamé parameter (small-strain)", 1e4, 0, 1e300, true},
      {"mu", "Pa", "shear modulus (small-strain)", 1e4, 0, 1e300, true},
  };
  return p;
}

bool StableNeoHookean::evaluate(const MaterialPoint& in, unsigned request,
                                MaterialResponse& out) const {
  if (request & kEnergy) {
    const double lambda = in.q[0], mu = in.q[1];
    const double mu_p = 4.0 / 3.0 * mu, lambda_p = lambda + 5.0 / 6.0 * mu;
    const double alpha = 1 + 0.75 * mu_p / lambda_p;
    const double Ic = in.F.squaredNorm(), J = in.F.determinant();
    out.energy = 0.5 * mu_p * (Ic - 3) + 0.5 * lambda_p * (J - alpha) * (J - alpha) -
                 0.5 * mu_p * std::log(Ic + 1);
    // Shift so that Ψ(I) = 0, as for every other model (a constant: P is unaffected).
    const double a0 = 1 - alpha;
    out.energy -= 0.5 * lambda_p * a0 * a0 - 0.5 * mu_p * std::log(4.0);
  }
  ad_stress_response<2>(in, request, out, [](const auto& F, const auto& q) {
    using S = typename std::decay_t<decltype(F)>::Scalar;
    return snh_stress<S>(F, q);
  });
  return true;
}

}  // namespace kelvin
