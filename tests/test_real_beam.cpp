// kelvin against REAL capture data: the bundled silicone-beam example
// (yaml/examples/silicone-beam-gravity-fit.yaml; srl-ethz/diffPD_sim2real, MIT), a
// 100 × 30 × 30 mm Dragon Skin 10 beam clamped at one end and released under
// gravity, three tip markers at 100 Hz. The fit (shear modulus and Newtonian
// viscosity, λ fixed) runs exactly as `kelvin fit` runs it, minus the report
// (~40 s on one core). The bands below were set from what the data and beam
// theory say, not from the fit's output; what the fit gave when they were set is
// quoted next to each.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "adjoint/marker_trajectory.hpp"
#include "fit/fit_loop.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {
namespace {

const std::string kExample =
    std::string(KELVIN_SOURCE_DIR) + "/yaml/examples/silicone-beam-gravity-fit.yaml";

/// Mean period of the ringing: successive minima of z(t), each refined by a
/// parabola through its frame and the two neighbours (frames 10 ms apart, period
/// ~130 ms); a minimum within 50 ms of the previous one is marker noise at a flat
/// trough and skipped. NaN when fewer than `count` minima are found.
double ringing_period(const std::vector<double>& t, const std::vector<double>& z, int count) {
  std::vector<double> minima;
  for (size_t k = 1; k + 1 < z.size() && static_cast<int>(minima.size()) < count; ++k) {
    if (!(z[k] < z[k - 1] && z[k] <= z[k + 1])) continue;
    const double curvature = z[k - 1] - 2 * z[k] + z[k + 1];
    const double shift = curvature > 0 ? 0.5 * (z[k - 1] - z[k + 1]) / curvature : 0.0;
    const double at = t[k] + shift * 0.5 * (t[k + 1] - t[k - 1]);
    if (minima.empty() || at - minima.back() > 0.05) minima.push_back(at);
  }
  if (static_cast<int>(minima.size()) < count) return NAN;
  return (minima.back() - minima.front()) / (count - 1);
}

/// Mean z of the tip markers per observed frame (all seen) and, for parameters p of
/// the problem's first experiment, the simulated mean z and marker RMS over the same
/// frames.
struct TipRun {
  std::vector<double> times, z_observed, z_simulated;
  double rms = 0;
};

TipRun run_tip(FitProblem& problem, const Eigen::VectorXd& p) {
  const MarkerTracks& observed = problem.experiment(0).scenario().markers.observed;
  const int markers = static_cast<int>(observed.names.size());
  TipRun r;
  r.times = observed.times;
  const MarkerTrajectory sim = simulate_markers(problem, 0, p, r.times, false);
  EXPECT_TRUE(sim.ok) << sim.error;
  if (!sim.ok) return r;
  double sum = 0;
  for (size_t f = 0; f < r.times.size(); ++f) {
    const Eigen::Map<const Eigen::Matrix3Xd> x(observed.xyz.col(static_cast<long>(f)).data(), 3,
                                               markers);
    EXPECT_TRUE(x.allFinite()) << "frame " << f << " has an occluded tip marker";
    r.z_observed.push_back(x.row(2).mean());
    r.z_simulated.push_back(sim.positions[f].row(2).mean());
    sum += (sim.positions[f] - x).squaredNorm();
  }
  r.rms = std::sqrt(sum / (markers * static_cast<double>(r.times.size())));
  return r;
}

/// run_tip for the scenario's own material.
TipRun run_tip(const Scenario& scenario) {
  FitProblem problem(scenario, {positive_fit_parameter("elastic.mu")});
  return run_tip(problem, problem.map().initial());
}

TEST(RealBeam, GravityReleaseFitFindsTheBendingStiffnessOfTheSilicone) {
  const Scenario scenario = load_scenario(kExample);
  ASSERT_TRUE(scenario.fit.present);
  FitProblem problem(scenario, scenario.fit.parameters);
  const ParameterMap& map = problem.map();
  ASSERT_EQ(map.size(), 2);
  ASSERT_EQ(map.label(0), "elastic.mu");
  ASSERT_EQ(map.label(1), "viscous.nu");

  // The options `kelvin fit` builds from the scenario's fit section.
  FitOptions o;
  o.algorithm = scenario.fit.algorithm;
  o.gradient.method = parse_gradient_method(scenario.fit.gradient);
  o.gradient.checkpoint_steps = scenario.fit.checkpoint_steps;
  o.gradient.segment = scenario.fit.segment;
  o.max_evaluations = scenario.fit.max_evaluations;
  o.ftol_rel = scenario.fit.ftol_rel;
  o.xtol_rel = scenario.fit.xtol_rel;
  o.max_seconds = scenario.fit.max_seconds;
  const FitOutcome fit = run_fit(problem, map.initial(), o);
  ASSERT_FALSE(fit.history.empty());
  EXPECT_EQ(fit.failures, 0);

  const double rms_start = fit.history.front().rms;  // evaluation 1, at the start
  const double rms_fit = fit.best.rms;
  const double mu = map.value(fit.p, 0), nu = map.value(fit.p, 1);
  const double lambda = scenario.material.elastic[0].params.at("lambda");
  const double E = mu * (3 * lambda + 2 * mu) / (lambda + mu);
  std::printf(
      "silicone beam: RMS %.4f -> %.4f mm after %d evaluations (%s); mu %.4g Pa, nu %.4g Pa s, "
      "lambda %.4g Pa (fixed): E %.4g Pa\n",
      rms_start * 1e3, rms_fit * 1e3, fit.evaluations, fit.stop_reason.c_str(), mu, nu, lambda, E);

  // RMS. At the start (μ 52 kPa from the data sheet's 100 % modulus, ν 50 Pa s) the
  // model sags a third too far and rings slowly and barely damped: 4.03 mm. At the
  // fit 0.50 mm, whose floor is the model's, not the noise's (0.03 mm): Tip 1 is a
  // ball 5.4 mm above the top face that the end face's rotation carries ~0.4 mm
  // further along the beam than the face point it is attached to (0.62 mm RMS in x),
  // and the first swing is ~1 mm deeper in the model. 0.6 mm allows 20 % over that.
  EXPECT_GT(rms_start, 3e-3);
  EXPECT_LT(rms_fit, 0.6e-3);
  EXPECT_LT(rms_fit / rms_start, 0.2);  // measured 0.124

  // Young's modulus. The data imply E ≈ 270–300 kPa for the silicone: the capture
  // settles 6.46 mm below its rest position, which for a clamped 100 mm beam of
  // 30 mm square section (ρ 1070) is E = ρgAL⁴/(8Iδ) = 271 kPa by Euler–Bernoulli,
  // 299 kPa with shear deflection (ν 0.45); the diffPD authors fitted 264 kPa with
  // another model. This mesh (three linear tetrahedra across) is stiffer in
  // bending than the material: measured with kelvin's static solver at E 264 kPa,
  // ν 0.45, the tip sags 4.80 mm on it and 6.66 mm on a 4× finer mesh (35k tets),
  // a factor 0.72. The band is that factor times 250–320 kPa: 180–230 kPa. The
  // fit gave 204 kPa (μ 69.7 kPa); the start is 153 kPa, outside the band.
  EXPECT_GT(E, 180e3);
  EXPECT_LT(E, 230e3);

  // The damping. The capture loses 24–30 % of its amplitude per cycle (peak-to-peak
  // ratios 0.70–0.76 over the window). In this model the logarithmic decrement grows
  // linearly with ν (measured: ratio 0.90 at ν 50, 0.725 at 160, 0.653 at 212), so
  // the decay alone asks for ν 136–178 Pa s; the fit also weighs the first swing,
  // which the model overshoots, and went to 212. Band: from 10 % under the decay's
  // value to 300 Pa s, where the model would lose 45 % per cycle, 1.5× the
  // capture's largest loss. The start, 50 Pa s, is outside.
  EXPECT_GT(nu, 120);
  EXPECT_LT(nu, 300);

  // The ringing: the fitted model's period matches the capture's within 2 %
  // (capture 129.2 ms, model 130.7 ms): the fitted stiffness is dynamic as well as
  // static, against the same mass.
  const TipRun tip = run_tip(problem, fit.p);
  ASSERT_EQ(tip.z_simulated.size(), tip.times.size());
  const double period_observed = ringing_period(tip.times, tip.z_observed, 8);
  const double period_simulated = ringing_period(tip.times, tip.z_simulated, 8);
  ASSERT_TRUE(std::isfinite(period_observed) && std::isfinite(period_simulated));
  std::printf("ringing period: capture %.2f ms, fitted model %.2f ms\n", period_observed * 1e3,
              period_simulated * 1e3);
  EXPECT_NEAR(period_observed, 0.129, 0.002);  // the capture itself: 7.7 Hz, not 10–12
  EXPECT_NEAR(period_simulated / period_observed, 1.0, 0.02);
}

TEST(RealBeam, HangingWeightIsAMassNotJustAForce) {
  // The 52 g release, run with the gravity fit's material (a prediction: nothing
  // fitted to this capture). The weight's inertia is half the beam's own mass, so it
  // sets the ringing: the capture rings at 230 ms; with the weight as a `mass:` the
  // model rings at 237 ms (+3 %) and leaves 3.34 mm RMS (most of it damping that a
  // Newtonian viscosity cannot carry from 7.7 Hz to 4.3 Hz, see the example's
  // header); as the same weight without inertia (`force:`) it rings near the unloaded
  // beam's 131 ms and leaves 5.4 mm.
  Scenario with_mass =
      load_scenario(std::string(KELVIN_SOURCE_DIR) + "/yaml/examples/silicone-beam-load52.yaml");
  ASSERT_EQ(with_mass.loads.size(), 1u);
  Scenario with_force = with_mass;
  LoadSpec& w = with_force.loads[0];
  w.force = w.mass * with_force.gravity;
  w.mass = 0;
  const TipRun m = run_tip(with_mass), f = run_tip(with_force);
  const double observed = ringing_period(m.times, m.z_observed, 5);
  const double mass_period = ringing_period(m.times, m.z_simulated, 5);
  const double force_period = ringing_period(f.times, f.z_simulated, 5);
  ASSERT_TRUE(std::isfinite(observed) && std::isfinite(mass_period) && std::isfinite(force_period));
  std::printf(
      "52 g release: capture period %.1f ms; weight as mass %.1f ms, RMS %.2f mm; as force "
      "%.1f ms, RMS %.2f mm\n",
      observed * 1e3, mass_period * 1e3, m.rms * 1e3, force_period * 1e3, f.rms * 1e3);
  EXPECT_NEAR(observed, 0.230, 0.005);
  // Spring–mass with the beam's effective 23 g: √((23 + 52)/23) = 1.8× the period.
  EXPECT_NEAR(mass_period / observed, 1.0, 0.05);
  EXPECT_LT(force_period / observed, 0.7);
  EXPECT_LT(m.rms, 4e-3);
  EXPECT_GT(f.rms, 1.4 * m.rms);
}

}  // namespace
}  // namespace kelvin
