// Viscous models in dynamic runs: Rayleigh damping of a cantilever gives the modal
// damping ratio ζ = α₀/(2ω) + α₁ω/2; power-law with h = 1 is Newtonian exactly;
// every viscous model damps (energy decreases monotonically).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "tests/cantilever_fixture.hpp"

using namespace kelvin;
using namespace kelvin::test;

namespace {

MaterialTerm term(const std::string& model, std::vector<double> q) {
  return {create_builtin_material(model), Eigen::Map<Eigen::VectorXd>(q.data(), q.size()), {}};
}

/// Decay rate ζω of the first mode from a least-squares fit of ln|peak| against
/// time over the minima of its modal coordinate (parabolic refinement). Rayleigh
/// damping keeps the modes decoupled, so the modal coordinate is a pure damped
/// oscillation: the faster or slower decay of other modes does not enter.
double decay_rate(const FreeVibration& fv) {
  std::vector<double> t, lnA;
  for (size_t k = 1; k + 1 < fv.modal.size(); ++k) {
    const double a = fv.modal[k - 1], b = fv.modal[k], c = fv.modal[k + 1];
    if (!(b < a && b <= c && b < 0)) continue;
    const double denom = a - 2 * b + c, s = 0.5 * (a - c) / denom;
    const double dt = fv.t[k] - fv.t[k - 1];
    t.push_back(fv.t[k] + s * dt);
    lnA.push_back(std::log(-(b - 0.25 * (a - c) * s)));
  }
  EXPECT_GE(t.size(), 4u);
  // Skip the first extremum: higher modes (damped faster) still contribute there.
  const size_t n = t.size() - 1;
  double st = 0, sa = 0, stt = 0, sta = 0;
  for (size_t k = 1; k < t.size(); ++k)
    st += t[k], sa += lnA[k], stt += t[k] * t[k], sta += t[k] * lnA[k];
  return -(n * sta - st * sa) / (n * stt - st * st);
}

}  // namespace

TEST(Damping, RayleighGivesTheAnalyticModalDampingRatio) {
  // Undamped first-mode frequency of this mesh, then three damping mixes.
  const Mode mode = first_mode(make_beam(2, 0.0));
  const double f0 = mode.frequency, w = 2 * M_PI * f0;
  struct Case {
    double alpha0, alpha1;
  };
  const Case cases[] = {{0.04 * w, 0}, {0, 0.04 / w}, {0.02 * w, 0.02 / w}};
  for (const Case& c : cases) {
    const double zeta_theory = c.alpha0 / (2 * w) + c.alpha1 * w / 2;
    const FreeVibration fv =
        release(2, 6 / f0, 600, 1e-8, {term("rayleigh", {c.alpha0, c.alpha1})}, &mode.shape);
    const double zeta = decay_rate(fv) / w;
    std::printf("  alpha0 %.4g 1/s, alpha1 %.4g s: zeta %.5f (theory %.5f, %.2f%% off)\n", c.alpha0,
                c.alpha1, zeta, zeta_theory, 100 * (zeta / zeta_theory - 1));
    EXPECT_NEAR(zeta, zeta_theory, 0.02 * zeta_theory);
  }
}

TEST(Damping, PowerLawWithUnitIndexIsNewtonianExactly) {
  const double f = theory_frequency();
  const FreeVibration a = release(2, 2 / f, 80, 1e-8, {term("newtonian", {20.0})});
  const FreeVibration b = release(2, 2 / f, 80, 1e-8, {term("power-law", {20.0, 1.0})});
  double diff = 0, scale = 0;
  for (size_t k = 0; k < a.tip.size(); ++k) {
    diff = std::max(diff, std::abs(a.tip[k] - b.tip[k]));
    scale = std::max(scale, std::abs(a.tip[k]));
  }
  std::printf("  max |newtonian - power-law(h=1)| tip difference: %.3e m of %.3e m\n", diff, scale);
  EXPECT_LE(diff, 1e-12 * scale);
}

TEST(Damping, EveryViscousModelDissipatesEnergy) {
  const double f = theory_frequency();
  for (const auto& [model, q] : std::vector<std::pair<std::string, std::vector<double>>>{
           {"newtonian", {2e4}},
           {"power-law", {2e4, 0.7}},
           {"rayleigh", {10.0, 1e-4}},
           {"strain-damping", {2e4, 5e4, 0.0}}}) {
    const FreeVibration fv = release(2, 2 / f, 80, 1e-8, {term(model, q)});
    for (size_t k = 1; k < fv.energy.size(); ++k)
      EXPECT_LE(fv.energy[k], fv.energy[k - 1] * (1 + 1e-9)) << model << " at t = " << fv.t[k];
    EXPECT_LT(fv.energy.back(), 0.9 * fv.energy.front()) << model;
  }
}
