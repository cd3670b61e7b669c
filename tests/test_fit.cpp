// Validation of `kelvin fit` on synthetic captures made by kelvin itself with known
// parameters: noise-free recovery from a start 2× off, Gaussian marker noise with
// Gauss–Newton standard errors, occlusion in bursts, and the command line (outputs,
// --resume, SIGINT).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <numbers>
#include <numeric>
#include <random>
#include <set>
#include <sstream>

#include "adjoint/uncertainty.hpp"
#include "engine/csv.hpp"
#include "fit/fit_context.hpp"
#include "fit/fit_loop.hpp"
#include "fit/fit_state.hpp"
#include "test_support.hpp"

namespace kelvin {
namespace {

using test::fs::path;

/// A motion of the clamped end: amplitudes (m) and frequencies (Hz) along y and z.
struct Motion {
  double amplitude_y, amplitude_z, frequency_y, frequency_z, end;
};
// The shaken bar of test_support.hpp, shaken harder (4 and 3 mm) for 0.2 s.
constexpr Motion kShaken{0.004, 0.003, 17, 13, 0.2};
// A slow sway (8 and 6 mm at 3 and 2 Hz) for 0.4 s: strain rates several times
// lower than kShaken's, which is what separates ν from the flow index h.
constexpr Motion kSlow{0.008, 0.006, 3, 2, 0.4};

/// The bar with four markers along its length sampled at 1 kHz, simulated at `rtol`
/// (atol 1e-4 × rtol m).
std::string bar(const std::string& material, const std::string& observed = "",
                const std::string& fit = "", const Motion& motion = kShaken, double rtol = 1e-7) {
  test::ShakenBar bar;
  bar.name = "fit-bar";
  bar.material = material.substr(1);  // the constants below start with a newline
  bar.amplitude_y = motion.amplitude_y;
  bar.amplitude_z = motion.amplitude_z;
  bar.frequency_y = motion.frequency_y;
  bar.frequency_z = motion.frequency_z;
  bar.end = motion.end;
  bar.output_rate = 1000;
  bar.rtol = rtol;
  bar.atol = 1e-4 * rtol;
  bar.tail = R"(markers:
  rest:
    - { name: tip, at: [0.06, 0.01, 0.01] }
    - { name: tip_top, at: [0.06, 0.0, 0.02] }
    - { name: mid, at: [0.03, 0.01, 0.02] }
    - { name: quarter, at: [0.015, 0.02, 0.0] }
)";
  if (!observed.empty()) bar.tail += "  observed: " + observed + "\n";
  return test::shaken_bar_yaml(bar) + fit;
}

const std::string kTruth = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 6.0e5, mu: 3.0e5 }
  viscous: { model: power-law, nu: 20, h: 0.8 })";
const double kTrue[] = {6.0e5, 3.0e5, 20};  // λ, μ, ν (h stays at the truth)
// Every fitted parameter 2× off the truth.
const std::string kStart = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 1.2e6, mu: 1.5e5 }
  viscous: { model: power-law, nu: 40, h: 0.8 })";
// The flow index h is not fitted: on this 0.2 s motion the strain rates span too
// narrow a range to separate ν from h (ν γ̇^(h−1) is nearly one number), and a
// four-parameter fit creeps along that valley (see the issue note).
const std::string kFitSection = R"(
fit:
  parameters: [elastic.lambda, elastic.mu, viscous.nu]
  max_evaluations: 80
  ftol_rel: 1.0e-14
  xtol_rel: 1.0e-9
)";

/// Rewrites a wide marker CSV: adds N(0, σ²) to every coordinate, then blanks
/// `fraction` of each marker's frames in bursts of `burst` consecutive frames.
std::string perturb_tracks(const std::string& file, const path& out, double sigma, double fraction,
                           int burst, unsigned seed) {
  MarkerTracks tracks = read_marker_tracks(file);
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, sigma);
  if (sigma > 0) tracks.xyz = tracks.xyz.unaryExpr([&](double v) { return v + noise(rng); });
  const int frames = static_cast<int>(tracks.times.size());
  const int bursts = static_cast<int>(std::lround(fraction * frames / burst));
  for (int m = 0; m < static_cast<int>(tracks.names.size()); ++m) {
    // Bursts in disjoint slots so that exactly `fraction` of the frames go missing.
    std::vector<int> slots(frames / burst);
    std::iota(slots.begin(), slots.end(), 0);
    std::shuffle(slots.begin(), slots.end(), rng);
    for (int b = 0; b < bursts; ++b)
      for (int f = slots[b] * burst; f < slots[b] * burst + burst; ++f)
        tracks.xyz.block(3 * m, f, 3, 1).setConstant(std::nan(""));
  }
  std::ostringstream csv;
  csv << "t";
  for (const auto& n : tracks.names) csv << "," << n << "_x," << n << "_y," << n << "_z";
  csv << "\n";
  csv.precision(17);
  for (int f = 0; f < frames; ++f) {
    csv << tracks.times[f];
    for (int r = 0; r < tracks.xyz.rows(); ++r) {
      csv << ",";
      if (!std::isnan(tracks.xyz(r, f))) csv << tracks.xyz(r, f);
    }
    csv << "\n";
  }
  test::write_text(out, csv.str());
  return out.string();
}

struct Fitted {
  FitOutcome outcome;
  Eigen::VectorXd q;  // model units
  std::unique_ptr<Scenario> scenario;
  std::unique_ptr<FitProblem> problem;
};

Fitted fit(const path& dir, const std::string& tracks, const std::string& start = kStart,
           const std::string& fit_section = kFitSection, double start_tolerance_scale = 1,
           double rtol = 1e-7, bool gauss_newton_start = false, double precision = 0,
           double start_objective = NAN) {
  Fitted f;
  test::write_text(dir / "fit.yaml", bar(start, tracks, fit_section, kShaken, rtol));
  f.scenario = std::make_unique<Scenario>(load_scenario((dir / "fit.yaml").string()));
  f.problem = std::make_unique<FitProblem>(*f.scenario, f.scenario->fit.parameters);
  FitOptions o;
  o.max_evaluations = f.scenario->fit.max_evaluations;
  o.ftol_rel = f.scenario->fit.ftol_rel;
  o.xtol_rel = f.scenario->fit.xtol_rel;
  o.start_tolerance_scale = start_tolerance_scale;
  o.gauss_newton_start = gauss_newton_start;
  o.precision = precision;
  o.start_objective = start_objective;
  f.outcome = run_fit(*f.problem, f.problem->map().initial(), o);
  f.q.resize(f.problem->map().size());
  for (int j = 0; j < f.q.size(); ++j) f.q[j] = f.problem->map().value(f.outcome.p, j);
  return f;
}

/// λ and μ within `tolerance`, ν within `nu_tolerance` (default: the same), and h
/// within `tolerance` when it was fitted.
void expect_recovered(const Fitted& f, double tolerance, double nu_tolerance = 0) {
  const double truth[] = {kTrue[0], kTrue[1], kTrue[2], 0.8};
  ASSERT_GE(f.q.size(), 3);
  ASSERT_LE(f.q.size(), 4);
  for (int j = 0; j < f.q.size(); ++j)
    EXPECT_NEAR(f.q[j] / truth[j], 1.0, j == 2 && nu_tolerance > 0 ? nu_tolerance : tolerance)
        << f.problem->map().label(j) << " fitted " << f.q[j] << " true " << truth[j] << " after "
        << f.outcome.evaluations << " evaluations (" << f.outcome.stop_reason << ")";
}

/// Records of evaluations at tolerances below the scenario's (the accuracy
/// probe's), each checked to be a re-simulation of the best point of its moment.
int accuracy_probes(const FitOutcome& outcome) {
  int probes = 0;
  Eigen::VectorXd best;
  for (const FitRecord& r : outcome.history) {
    if (r.tolerance_scale < 1) {
      ++probes;
      EXPECT_EQ(r.tolerance_scale, 0.1);
      EXPECT_FALSE(r.accepted);
      EXPECT_TRUE(r.p == best) << "evaluation " << r.evaluation;
    }
    if (r.accepted) best = r.p;
  }
  return probes;
}

// One stage at the scenario's tolerances (start_tolerance_scale 1).
TEST(Fit, NoiseFreeRecoversNeoHookeanAndViscosityFromTwiceOff) {
  const path dir = test::scratch("fit-noise-free");
  const Fitted f = fit(dir, test::simulate_tracks(dir, "truth", bar(kTruth)));
  expect_recovered(f, 1e-3);
  EXPECT_LT(f.outcome.best.rms, 1e-6);  // metres: the truth is in the model class
  EXPECT_EQ(f.outcome.failures, 0);
  EXPECT_EQ(f.outcome.stop_reason.rfind("converged", 0), 0u) << f.outcome.stop_reason;
  EXPECT_LE(accuracy_probes(f.outcome), 1);
}

// One stage at loose tolerances (rtol 1e-3) against tracks simulated at 1e-7: near
// the minimum Φ is mostly integration error, and line searches stall. Φ's accuracy
// is then measured once, when a line search first looks stuck (the best point of
// that moment re-simulated 10× tighter), and the stall ends the fit with advice.
TEST(Fit, OneStageStallAtLooseTolerancesMeasuresTheAccuracyOnce) {
  const path dir = test::scratch("fit-loose");
  const Fitted f =
      fit(dir, test::simulate_tracks(dir, "truth", bar(kTruth)), kStart, kFitSection, 1, 1e-3);
  const FitOutcome& out = f.outcome;
  EXPECT_EQ(accuracy_probes(out), 1);
  EXPECT_NE(out.stop_reason.find("within the objective's accuracy"), std::string::npos)
      << out.stop_reason;
  EXPECT_LT(out.best.rms, 0.1 * out.history.front().rms);
}

// The fit in stages (FitOptions::start_tolerance_scale): 100× the scenario's
// tolerances first, then 10×, then the scenario's. The early stages only bring the
// start nearer; the last one must reach the same accuracy as a one-stage fit.
TEST(Fit, CoarseStagesHandOverToTheScenarioTolerances) {
  const path dir = test::scratch("fit-stages");
  const Fitted f =
      fit(dir, test::simulate_tracks(dir, "truth", bar(kTruth)), kStart, kFitSection, 100);
  expect_recovered(f, 1e-3);
  const auto& h = f.outcome.history;
  ASSERT_FALSE(h.empty());
  EXPECT_EQ(h.front().tolerance_scale, 100);
  EXPECT_LE(f.outcome.best.tolerance_scale, 1);
  std::vector<double> stages;
  for (size_t i = 0; i < h.size(); ++i) {
    if (i > 0) {
      EXPECT_LE(h[i].tolerance_scale, h[i - 1].tolerance_scale) << "evaluation " << i;
    }
    if (stages.empty() || stages.back() != h[i].tolerance_scale)
      stages.push_back(h[i].tolerance_scale);
  }
  EXPECT_GE(stages.size(), 3u);  // 100×, 10×, 1× (and tighter if the last one stalled)
  EXPECT_EQ(stages[1], 10);
  EXPECT_EQ(stages[2], 1);
}

// With 20 % of the frames hidden in bursts, L-BFGS stalls in the λ–μ–ν valley (λ
// 1.9× off, RMS 0.011 mm, the line search unable to see a decrease through Φ's
// integration noise); run_fit restarts it in Gauss–Newton-scaled parameters, whose
// first step lands next to the truth. The observed tracks next to each gap take
// one-sided second-order slopes: with secants there the fit converged to λ 1.5e-3
// and ν 1.2e-3 off the truth; now to λ 3e-4, μ 4e-5, ν 9e-5 (kelvin fit, 101
// evaluations, at the misfit floor RMS 0.0002 mm of the truth itself).
TEST(Fit, OccludedBurstsStillRecoverTheParameters) {
  const path dir = test::scratch("fit-occluded");
  const std::string tracks = perturb_tracks(test::simulate_tracks(dir, "truth", bar(kTruth)),
                                            dir / "occluded.csv", 0.0, 0.2, 5, 7);
  const MarkerTracks t = read_marker_tracks(tracks);
  const double missing = t.xyz.array().isNaN().cast<double>().sum() / t.xyz.size();
  EXPECT_NEAR(missing, 0.2, 0.02);
  const Fitted f = fit(dir, tracks);
  expect_recovered(f, 1e-3);
}

// All four parameters of the issue (λ, μ, ν, h), each 2× off, from two motions of
// the same bar fitted jointly (Real2Sim Fig. 13): the 17/13 Hz shaking alone leaves
// ν γ̇^(h−1) nearly one number (a single-motion fit stopped at ν 26, h 0.62), the
// slow sway adds strain rates several times lower. Long (~7 min): ctest -L long.
TEST(FitLong, FlowIndexFromTwoMotionsAtDifferentStrainRates) {
  const path dir = test::scratch("fit-two-motions");
  const std::string start = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 1.2e6, mu: 1.5e5 }
  viscous: { model: power-law, nu: 40, h: 1.6 })";
  const std::string fast = test::simulate_tracks(dir, "truth-fast", bar(kTruth));
  const std::string slow = test::simulate_tracks(dir, "truth-slow", bar(kTruth, "", "", kSlow));
  test::write_text(dir / "slow.yaml", bar(start, slow, "", kSlow));
  const Fitted f = fit(dir, fast, start, R"(
fit:
  parameters: [elastic.lambda, elastic.mu, viscous.nu, viscous.h]
  experiments: [slow.yaml]
  max_evaluations: 250
  ftol_rel: 1.0e-14
  xtol_rel: 1.0e-9
)");
  ASSERT_EQ(f.problem->num_experiments(), 2);
  expect_recovered(f, 1e-3);
  // Line-search trials far out (a flow index of 3, say) may fail, as the issue
  // allows: the fit backs off. Each must say why and where, and none is a best.
  for (const FitRecord& r : f.outcome.history)
    if (!r.ok) {
      EXPECT_FALSE(r.accepted);
      EXPECT_NE(r.error.find("t = "), std::string::npos) << r.error;
      std::printf("failed trial %d: %s\n", r.evaluation, r.error.c_str());
    }
}

// The noise test is about the statistics at the optimum, not about getting there
// (the noise-free test starts 2× off): it starts 25% off, which saves half the
// evaluations.
const std::string kStartNear = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 7.5e5, mu: 2.4e5 }
  viscous: { model: power-law, nu: 25, h: 0.8 })";

TEST(Fit, MarkerNoiseGivesRmsAtTheNoiseLevelAndHonestStandardErrors) {
  const double sigma = 1e-3;
  const path dir = test::scratch("fit-noise");
  const std::string tracks = perturb_tracks(test::simulate_tracks(dir, "truth", bar(kTruth)),
                                            dir / "noisy.csv", sigma, 0.0, 1, 11);
  const Fitted f = fit(dir, tracks, kStartNear);
  const ParameterUncertainty u = gauss_newton_uncertainty(*f.problem, f.outcome.p);
  ASSERT_TRUE(u.ok) << u.error;
  // Residuals at the capture frames: per coordinate, the noise level.
  EXPECT_NEAR(u.sigma / sigma, 1.0, 0.1);
  // Φ's continuous RMS distance sees the noise through the observed track's spline:
  // on this uniform grid it weighs the frames by the cardinal cubic spline L, so
  // E r² = σ² ∫L² per coordinate (2/3 for a linear track). By Parseval, with
  // L̂(ω) = sinc⁴(ω/2) · 3/(2 + cos ω) and Σₖ sinc⁸ folded into the symbol of the
  // degree-7 B-spline (2416 + 2·1191 cos ω + 2·120 cos 2ω + 2 cos 3ω)/5040,
  //   ∫L² = (1/2π) ∫_{−π}^{π} 9 B₇(ω) / (2 + cos ω)² dω = 0.8742…
  // (the trapezoid rule converges geometrically for this periodic integrand).
  double spline_noise = 0;
  constexpr int kNodes = 256;
  for (int k = 0; k < kNodes; ++k) {
    const double w = 2 * std::numbers::pi * k / kNodes, c = std::cos(w);
    spline_noise += 9 * (2416 + 2382 * c + 240 * std::cos(2 * w) + 2 * std::cos(3 * w)) / 5040 /
                    ((2 + c) * (2 + c)) / kNodes;
  }
  EXPECT_NEAR(f.outcome.best.rms / (std::sqrt(3.0 * spline_noise) * sigma), 1.0, 0.1);
  for (int j = 0; j < 3; ++j) {
    const double z = (f.q[j] - kTrue[j]) / u.std_error[j];
    EXPECT_LT(std::abs(z), 3.0) << f.problem->map().label(j) << " fitted " << f.q[j] << " ± "
                                << u.std_error[j] << " true " << kTrue[j];
  }
}

// A caller that resolves only a relative change P of Φ (the diagnosis, from its χ²
// thresholds) gets a fit that ends at the first window of accepted moves gaining less
// than P, and says so; here P is far above Φ's accuracy at rtol 1e-7.
TEST(Fit, APrecisionAskedForEndsTheFitAtTheFirstPlateauOfThatSize) {
  const path dir = test::scratch("fit-precision");
  const std::string tracks = perturb_tracks(test::simulate_tracks(dir, "truth", bar(kTruth)),
                                            dir / "noisy.csv", 1e-3, 0.0, 1, 11);
  const double precision = 0.01;
  const Fitted f = fit(dir, tracks, kStart, kFitSection, 1, 1e-7, false, precision);
  EXPECT_NE(f.outcome.stop_reason.find("the precision asked for (1 %)"), std::string::npos)
      << f.outcome.stop_reason;
  std::vector<double> best;  // the best Φ after each accepted move
  for (const FitRecord& r : f.outcome.history)
    if (r.accepted) best.push_back(r.objective);
  constexpr size_t w = fit_detail::kPlateauWindow;
  ASSERT_GT(best.size(), w);
  const auto gain = [&](size_t i) { return (best[i - w] - best[i]) / best[i]; };
  EXPECT_LT(gain(best.size() - 1), precision);
  for (size_t i = w; i + 1 < best.size(); ++i) EXPECT_GE(gain(i), precision) << "move " << i;
  EXPECT_LT(best.back(), 0.1 * best.front());  // it did fit: the start is twice off
}

// A coarse stage's best, re-measured at the scenario's tolerances, that gains less
// than the precision on the start's value there (FitOptions::start_objective) ends
// the fit at that re-measure: its gain was the coarse integration's. Here the start's
// value is given as 0, so no gain can count, and the coarse stage's moves stand.
TEST(Fit, ACoarseGainLostAtTheScenarioTolerancesEndsTheFit) {
  const path dir = test::scratch("fit-coarse-gain-lost");
  const std::string tracks = perturb_tracks(test::simulate_tracks(dir, "truth", bar(kTruth)),
                                            dir / "noisy.csv", 1e-3, 0.0, 1, 11);
  const Fitted f = fit(dir, tracks, kStart, kFitSection, 10, 1e-7, false, 0.01, 0.0);
  EXPECT_NE(f.outcome.stop_reason.find("re-measured at the scenario's tolerances"),
            std::string::npos)
      << f.outcome.stop_reason;
  const auto& h = f.outcome.history;
  ASSERT_GE(h.size(), 2u);
  EXPECT_EQ(h.back().tolerance_scale, 1);
  EXPECT_TRUE(h.back().accepted);  // the re-measure of the coarse best
  for (size_t i = 0; i + 1 < h.size(); ++i) EXPECT_EQ(h[i].tolerance_scale, 10) << i;
  EXPECT_LT(h.back().objective, 0.5 * h.front().objective);
}

TEST(Fit, AGaussNewtonStepThatPredictsAGainWithinTheAccuracyEndsTheFit) {
  // Noisy tracks at rtol 1e-4, started near the truth in Gauss–Newton-scaled
  // parameters: once the model predicts a gain within Φ's accuracy the fit stops
  // there instead of spending its line searches on integration noise (here after
  // four moves and the accuracy probe, at the RMS a 2×-farther start reaches in 17
  // evaluations, 1.6236 mm), and the parameters it stops at are the truth within
  // their standard errors.
  const double sigma = 1e-3;
  const path dir = test::scratch("fit-predicted-gain");
  const std::string tracks = perturb_tracks(test::simulate_tracks(dir, "truth", bar(kTruth)),
                                            dir / "noisy.csv", sigma, 0.0, 1, 11);
  // λ is not resolved by this motion at rtol 1e-4 (JᵀJ singular in it): μ and ν only.
  const std::string start = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 6.0e5, mu: 2.85e5 }
  viscous: { model: power-law, nu: 22, h: 0.8 })";
  const Fitted f = fit(dir, tracks, start,
                       "fit: { parameters: [elastic.mu, viscous.nu], max_evaluations: 80, "
                       "ftol_rel: 1.0e-14, xtol_rel: 1.0e-9 }\n",
                       1, 1e-4, true);
  EXPECT_NE(f.outcome.stop_reason.find("Gauss–Newton step from the best point predicts"),
            std::string::npos)
      << f.outcome.stop_reason;
  const ParameterUncertainty u = gauss_newton_uncertainty(*f.problem, f.outcome.p);
  ASSERT_TRUE(u.ok) << u.error;
  for (int j = 0; j < 2; ++j) {
    const double z = (f.q[j] - kTrue[j + 1]) / u.std_error[j];
    EXPECT_LT(std::abs(z), 3.0) << f.problem->map().label(j) << " fitted " << f.q[j] << " ± "
                                << u.std_error[j] << " true " << kTrue[j + 1];
  }
}

// A Lamé λ fitted far below μ (V07's nominal fit drove it to 0.0036 Pa beside μ at
// 1.4e5 Pa) moves the markers too little for the data to place it. The Gauss–Newton
// scaling holds it rather than scaling it by its vanishing sensitivity (every V07
// refit's first scaled step moved ln λ by 4.8e6 and ended on refused trials after
// one evaluation), and μ and ν still come back from 10 % off.
TEST(Fit, AParameterTheDataCannotPlaceIsHeldByTheGaussNewtonScaling) {
  const path dir = test::scratch("fit-unresolved");
  const std::string truth = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 0.01, mu: 3.0e5 }
  viscous: { model: power-law, nu: 20, h: 0.8 })";
  const std::string start = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 0.01, mu: 2.7e5 }
  viscous: { model: power-law, nu: 22, h: 0.8 })";
  const std::string tracks = perturb_tracks(test::simulate_tracks(dir, "truth", bar(truth)),
                                            dir / "noisy.csv", 1e-4, 0.0, 1, 5);
  const Fitted f = fit(dir, tracks, start, kFitSection, 1, 1e-7, true);
  const ParameterUncertainty u = gauss_newton_uncertainty(*f.problem, f.problem->map().initial());
  ASSERT_EQ(u.unresolved, std::vector<int>{0}) << u.error;
  EXPECT_EQ(u.root_inverse.row(0).norm(), 0);
  EXPECT_GT(u.root_inverse.row(1).norm(), 0);
  // Its standard error is still reported (the covariance is not refused).
  EXPECT_TRUE(u.ok) << u.error;
  // Held where it is, it has none, and the others' are their errors given it:
  // smaller (conditioning cannot widen them), the more so for μ, whose column λ's
  // nearly repeats.
  const Eigen::VectorXd held =
      standard_errors_with_unresolved_held(u, f.problem->map(), f.problem->map().initial());
  EXPECT_TRUE(std::isnan(held[0]));
  for (int j = 1; j < 3; ++j) {
    EXPECT_GT(held[j], 0) << j;
    EXPECT_LE(held[j], u.std_error[j] * (1 + 1e-9)) << j;
  }
  EXPECT_LT(held[1], 0.05 * u.std_error[1]);         // μ: 0.5 kPa given λ, 53 kPa without
  EXPECT_NEAR(held[2] / u.std_error[2], 1.0, 1e-3);  // ν's column is not λ's
  EXPECT_NEAR(f.q[1] / 3.0e5, 1.0, 1e-3)
      << f.outcome.stop_reason << " after " << f.outcome.evaluations;
  EXPECT_NEAR(f.q[2] / 20, 1.0, 1e-2) << f.outcome.stop_reason;
  EXPECT_EQ(f.outcome.stop_reason.rfind("converged", 0), 0u) << f.outcome.stop_reason;
}

}  // namespace
}  // namespace kelvin

namespace kelvin {
namespace {

/// A short fit for the command line: 0.05 s of the bar, μ and ν from 2× off.
test::fs::path cli_scenario(const std::string& name) {
  const path dir = test::scratch(name);
  std::string truth = bar(kTruth);
  const auto shorten = [](std::string yaml) {
    return yaml.replace(yaml.find("end: 0.2"), 8, "end: 0.05");
  };
  const std::string tracks = test::simulate_tracks(dir, "truth", shorten(truth));
  test::write_text(dir / "fit.yaml",
                   shorten(bar(kStart, tracks,
                               "fit: { parameters: [elastic.mu, viscous.nu], max_evaluations: 3 "
                               "}\n")));
  return dir;
}

int history_rows(const path& file) {
  const std::string text = test::read_text(file);
  return static_cast<int>(std::count(text.begin(), text.end(), '\n')) - 1;
}

TEST(FitCli, WritesOutputsResumesAndTheFittedScenarioRuns) {
  const path dir = cli_scenario("fit-cli");
  const std::string out = (dir / "out").string();
  const auto first = test::run_kelvin("fit " + (dir / "fit.yaml").string() + " -o " + out);
  ASSERT_EQ(first.exit_code, 0) << first.out;
  EXPECT_NE(first.out.find("report: " + out + "/report.md"), std::string::npos) << first.out;
  for (const char* f : {"fitted.yaml", "history.csv", "fit-state.yaml", "marker-rms.csv",
                        "report.md", "objective.svg", "track-1.svg"})
    EXPECT_TRUE(test::fs::exists(dir / "out" / f)) << f;
  EXPECT_EQ(history_rows(dir / "out" / "history.csv"), 3);

  // --resume continues the numbering up to the new budget.
  const auto resumed = test::run_kelvin("fit " + (dir / "fit.yaml").string() + " -o " + out +
                                        " --resume --max-evaluations 5");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.out;
  EXPECT_EQ(history_rows(dir / "out" / "history.csv"), 5);
  EXPECT_NE(test::read_text(dir / "out" / "history.csv").find("\n5,"), std::string::npos);

  const auto sim = test::run_kelvin("simulate " + out + "/fitted.yaml -q -o " + out + "/sim");
  EXPECT_EQ(sim.exit_code, 0) << sim.out;

  // A state edited to hold a parameter beyond its bounds is refused, not resumed.
  std::string state = test::read_text(dir / "out" / "fit-state.yaml");
  const size_t at = state.find(", best: ");
  ASSERT_NE(at, std::string::npos) << state;
  state.replace(at, state.find('}', at) - at, ", best: 1e308");
  test::write_text(dir / "out" / "fit-state.yaml", state);
  const auto edited = test::run_kelvin("fit " + (dir / "fit.yaml").string() + " -o " + out +
                                       " --resume --max-evaluations 6");
  EXPECT_EQ(edited.exit_code, 1) << edited.out;
  EXPECT_NE(edited.out.find("fit-state.yaml: parameters[0].best"), std::string::npos) << edited.out;
  EXPECT_NE(edited.out.find("outside its bounds"), std::string::npos) << edited.out;
}

TEST(FitCli, InterruptWritesTheBestSoFarAndSaysHowToResume) {
  const path dir = cli_scenario("fit-interrupt");
  const std::string out = (dir / "out").string();
  // Interrupt once the first evaluation is in the history.
  const std::string script = std::string(KELVIN_BINARY) + " fit " + (dir / "fit.yaml").string() +
                             " -o " + out + " --max-evaluations 50 > " + out +
                             ".log 2>&1 & pid=$!; while [ ! -s " + out +
                             "/fit-state.yaml ]; do sleep 0.05; done; kill -INT $pid; wait $pid";
  const int status = std::system(("bash -c '" + script + "'").c_str());
  EXPECT_EQ(WEXITSTATUS(status), 130);
  EXPECT_TRUE(test::fs::exists(dir / "out" / "fitted.yaml"));
  EXPECT_TRUE(test::fs::exists(dir / "out" / "report.md"));
  EXPECT_NE(test::read_text(out + ".log").find("--resume"), std::string::npos);
  EXPECT_LT(history_rows(dir / "out" / "history.csv"), 50);
}

/// The fitted parameters of a finished fit, by label, from its fit-state.yaml.
std::map<std::string, double> fitted_parameters(const path& state_file) {
  const FitState s = read_fit_state(state_file.string());
  std::map<std::string, double> p;
  for (size_t j = 0; j < s.labels.size(); ++j) p[s.labels[j]] = s.best[j];
  return p;
}

// SIGKILL leaves no chance to write anything: what was saved after each evaluation
// must be enough for --resume to reach the result of a fit that ran through. The
// kill lands at an evaluation drawn from the process id (different on every run).
TEST(FitCli, AFitKilledAtAnyEvaluationResumesToTheSameResult) {
  const path dir = cli_scenario("fit-sigkill");
  const std::string fit = std::string(KELVIN_BINARY) + " fit " + (dir / "fit.yaml").string();
  const std::string through = (dir / "through").string(), killed = (dir / "killed").string();
  const auto full = test::run_kelvin("fit " + (dir / "fit.yaml").string() + " -q -o " + through +
                                     " --max-evaluations 40");
  ASSERT_EQ(full.exit_code, 0) << full.out;
  const int total = history_rows(dir / "through" / "history.csv");
  ASSERT_LT(total, 40) << "the fit did not converge within its budget";

  // At least two evaluations before the end, so that the kill lands inside the fit.
  const int kill_at = 1 + static_cast<int>(getpid()) % std::max(1, total - 2);
  const std::string script = fit + " -q -o " + killed + " --max-evaluations 40 > " + killed +
                             ".log 2>&1 & pid=$!; while [ \"$(grep -c . " + killed +
                             "/history.csv 2>/dev/null || echo 0)\" -le " +
                             std::to_string(kill_at) +
                             " ]; do sleep 0.01; done; kill -KILL $pid; wait $pid";
  const int status = std::system(("bash -c '" + script + "'").c_str());
  EXPECT_EQ(WEXITSTATUS(status), 128 + SIGKILL) << "killed at evaluation " << kill_at;
  const int saved = history_rows(dir / "killed" / "history.csv");
  ASSERT_GE(saved, kill_at);
  ASSERT_LT(saved, total) << "the fit finished before the kill";

  // The resumed L-BFGS starts without the curvature pairs it had, so it may need more
  // evaluations than the fit that ran through (12 more measured in one case): a budget
  // that binds would compare a truncated fit with a converged one.
  const auto resumed = test::run_kelvin("fit " + (dir / "fit.yaml").string() + " -q -o " + killed +
                                        " --resume --max-evaluations 100");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.out;
  EXPECT_NE(test::read_text(dir / "killed" / "report.md").find("· converged: "), std::string::npos)
      << "the resumed fit stopped before converging (killed at evaluation " << kill_at << ")";
  // Each evaluation is numbered once, however the kill fell between the history and
  // the state being written.
  const std::string history = test::read_text(dir / "killed" / "history.csv");
  std::set<int> numbers;
  std::istringstream rows(history.substr(history.find('\n') + 1));
  for (std::string row; std::getline(rows, row);)
    EXPECT_TRUE(numbers.insert(std::stoi(row)).second) << "evaluation " << row << " twice";
  const auto a = fitted_parameters(dir / "through" / "fit-state.yaml");
  const auto b = fitted_parameters(dir / "killed" / "fit-state.yaml");
  ASSERT_EQ(a.size(), b.size());
  // The same optimum, not the same path: agreement is to the fit's own convergence
  // (log parameters).
  for (const auto& [label, value] : a)
    EXPECT_NEAR(b.at(label), value, 2e-3) << label << " (killed at evaluation " << kill_at << ")";
  EXPECT_TRUE(test::fs::exists(dir / "killed" / "fitted.yaml"));
}

// A full disk at any output step (emulated by a file-size limit, whose writes fail
// as ENOSPC would once SIGXFSZ is ignored): an error naming the file, no partial or
// temporary file left, and the fit resumable from what was saved.
TEST(FitCli, AFullDiskAtAnyOutputLeavesEveryFileWholeAndTheFitResumable) {
  const path dir = cli_scenario("fit-full-disk");
  const std::string out = (dir / "out").string();
  const std::string fit = "fit " + (dir / "fit.yaml").string() + " -q -o " + out;
  ASSERT_EQ(test::run_kelvin(fit + " --max-evaluations 2").exit_code, 0);
  int failures = 0, evaluations = 2;
  // Limits in KiB from below the smallest output to above the largest (the track plots).
  for (const int kib : {1, 2, 3, 4, 8, 16, 32}) {
    ++evaluations;
    const std::string script = "trap \"\" XFSZ; ulimit -f " + std::to_string(kib) + "; " +
                               KELVIN_BINARY + " " + fit + " --resume --max-evaluations " +
                               std::to_string(evaluations) + " > " + out + ".log 2>&1";
    const int status = std::system(("bash -c '" + script + "'").c_str());
    const std::string log = test::read_text(out + ".log");
    if (WEXITSTATUS(status) != 0) {
      ++failures;
      EXPECT_EQ(WEXITSTATUS(status), 2) << kib << " KiB: " << log;
      EXPECT_NE(log.find("write failed"), std::string::npos) << kib << " KiB: " << log;
      EXPECT_NE(log.find("File too large"), std::string::npos) << kib << " KiB: " << log;
    }
    // The adjoint's temporary file goes to memory once the disk is full: no trial fails.
    EXPECT_EQ(log.find("simulation failed"), std::string::npos) << kib << " KiB: " << log;
    for (const auto& f : test::fs::directory_iterator(dir / "out"))
      EXPECT_EQ(f.path().filename().string().find(".tmp."), std::string::npos)
          << kib << " KiB left " << f.path();
    const FitState state = read_fit_state((dir / "out" / "fit-state.yaml").string());
    EXPECT_EQ(history_rows(dir / "out" / "history.csv"), state.evaluations) << kib << " KiB";
  }
  EXPECT_GE(failures, 3);  // the small limits fail at different outputs
  const auto finished =
      test::run_kelvin(fit + " --resume --max-evaluations " + std::to_string(evaluations + 1));
  ASSERT_EQ(finished.exit_code, 0) << finished.out;
  EXPECT_EQ(read_fit_state((dir / "out" / "fit-state.yaml").string()).evaluations, evaluations + 1);
  const auto sim = test::run_kelvin("simulate " + out + "/fitted.yaml -q -o " + out + "/sim");
  EXPECT_EQ(sim.exit_code, 0) << sim.out;
}

}  // namespace
}  // namespace kelvin
