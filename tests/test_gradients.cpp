// Gradients of the marker misfit: adjoint vs forward sensitivities vs central
// finite differences, Taylor tests, the occlusion rule and segment-wise adjoints.
// Observed tracks are simulated by kelvin with known parameters; the fits start
// away from them so that the misfit and its gradient are far from zero.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <tuple>
#include <vector>

#include "adjoint/fit_problem.hpp"
#include "adjoint/gradient_check.hpp"
#include "gradient_agreement.hpp"
#include "test_support.hpp"
#include "yaml/scenario.hpp"
#include "yaml/scenario_simulation.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;

/// The shaken bar of test_support.hpp, two markers, sampled at 200 Hz.
std::string bar_yaml(const std::string& material, const std::string& extra = "") {
  test::ShakenBar bar;
  bar.material = material.substr(1);  // the constants below start with a newline
  bar.tail = extra;
  return test::shaken_bar_yaml(bar);
}

const std::string kMarkers = R"(
markers:
  rest:
    - { name: tip, at: [0.06, 0.01, 0.01] }
    - { name: mid, at: [0.03, 0.01, 0.02] }
)";

const std::string kTruthNeoHookean = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
  viscous: { model: power-law, nu: 20, h: 0.8 })";
const std::string kStartNeoHookean = R"(
  density: 1300
  elastic: { model: neo-hookean, lambda: 2.6e5, mu: 0.8e5 }
  viscous: { model: power-law, nu: 30, h: 0.9 })";
const std::string kTruthRayleigh = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
  viscous: { model: rayleigh, alpha0: 2.0, alpha1: 1.0e-3 })";
const std::string kStartRayleigh = R"(
  density: 1000
  elastic: { model: neo-hookean, lambda: 2.4e5, mu: 1.2e5 }
  viscous: { model: rayleigh, alpha0: 3.0, alpha1: 0.7e-3 })";

fs::path scratch(const std::string& name) {
  return test::scratch("gradients-" + name);
}

void write(const fs::path& path, const std::string& text) {
  test::write_text(path, text);
}

/// Simulates the truth and returns the path of its marker tracks.
std::string simulate_truth(const fs::path& dir, const std::string& material) {
  write(dir / "truth.yaml", bar_yaml(material, kMarkers));
  SimulationOptions o;
  o.outdir = (dir / "truth").string();
  const SimulationResult r = run_simulation(load_scenario((dir / "truth.yaml").string()), o);
  EXPECT_TRUE(r.completed) << r.error;
  return (dir / "truth" / "markers.csv").string();
}

Scenario fit_scenario(const fs::path& dir, const std::string& material, const std::string& tracks) {
  const std::string markers =
      kMarkers.substr(0, kMarkers.rfind('\n')) + "\n  observed: " + tracks + "\n";
  write(dir / "fit.yaml", bar_yaml(material, markers));
  return load_scenario((dir / "fit.yaml").string());
}

FitParameterSpec param(const std::string& target,
                       FitParameterSpec::Scope scope = FitParameterSpec::Scope::Global) {
  return positive_fit_parameter(target, scope);
}

using test::expect_methods_agree;

TEST(Gradients, GlobalNeoHookeanPowerLawAndDensity) {
  const fs::path dir = scratch("global");
  const Scenario s = fit_scenario(dir, kStartNeoHookean, simulate_truth(dir, kTruthNeoHookean));
  FitProblem problem(s, {param("elastic.lambda"), param("elastic.mu"), param("viscous.nu"),
                         param("viscous.h"), param("density")});
  ASSERT_EQ(problem.map().size(), 5);
  const GradientCheckReport r = check_gradient(problem, problem.map().initial(), {});
  expect_methods_agree(r);
  EXPECT_GT(r.rms, 1e-4);  // the start is far from the truth: the gradient is not noise
}

TEST(Gradients, ATaylorTestStartedInTheNoiseGrowsToResolvedSteps) {
  // At 100× the scenario's tolerances a first step of 2^-16 puts every level's
  // remainder (≈ c₂h²) under the integration noise (3e-14 here): the sequence must
  // grow upwards until three levels clear it (ten doublings, to 2^-6), and the rate
  // there is still 2.
  const fs::path dir = scratch("taylor-growth");
  const Scenario s = fit_scenario(dir, kStartNeoHookean, simulate_truth(dir, kTruthNeoHookean));
  FitProblem problem(s, {param("elastic.mu"), param("viscous.nu")});
  GradientCheckOptions o;
  o.forward = false;
  o.adjoint.tolerance_scale = 100;
  o.taylor_h0 = std::ldexp(1.0, -16);
  o.taylor_levels = 3;
  const GradientCheckReport r = check_gradient(problem, problem.map().initial(), o);
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_GT(r.added_levels, 0);
  EXPECT_GE(r.resolved_levels, 3);
  EXPECT_LE(r.h.front(), 1.0);
  EXPECT_NEAR(r.slope, 2.0, 0.2) << "first step " << r.h.front() << ", noise " << r.noise;
}

TEST(Gradients, RayleighPerRegionWithDensity) {
  const fs::path dir = scratch("rayleigh");
  const Scenario s = fit_scenario(dir, kStartRayleigh, simulate_truth(dir, kTruthRayleigh));
  auto halves = param("elastic.mu", FitParameterSpec::Scope::Boxes);
  halves.boxes = {{Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(0.03, 1, 1)}};  // + the rest
  auto density = param("density", FitParameterSpec::Scope::Boxes);
  density.boxes = halves.boxes;
  FitProblem problem(s, {halves, param("elastic.lambda"), param("viscous.alpha0"),
                         param("viscous.alpha1"), density});
  ASSERT_EQ(problem.map().size(), 7);
  expect_methods_agree(check_gradient(problem, problem.map().initial(), {}));
}

TEST(Gradients, PerElementFieldAdjointMatchesForwardSensitivities) {
  const fs::path dir = scratch("element");
  const Scenario s = fit_scenario(dir, kStartNeoHookean, simulate_truth(dir, kTruthNeoHookean));
  FitProblem problem(s, {param("elastic.mu", FitParameterSpec::Scope::PerElement)});
  ASSERT_EQ(problem.map().size(), s.mesh.num_tets());
  GradientCheckOptions o;
  o.max_parameters = 4;  // finite differences on a few entries; δ covers all of them
  expect_methods_agree(check_gradient(problem, problem.map().initial(), o));
}

/// The segment tests compare trajectories restarted at different times: each
/// restart's error is a fraction of the tolerance, so they run 10× tighter than the
/// other tests (at rtol 1e-9 the gradients of 4–7 segments and of one differed by
/// 0.9–1.7e-8).
Scenario tight(Scenario s) {
  s.solver.rtol = 1e-10;
  s.solver.atol = 1e-14;
  return s;
}

TEST(Gradients, SegmentedAdjointMatchesSingleSegment) {
  const fs::path dir = scratch("segments");
  const Scenario s =
      tight(fit_scenario(dir, kStartNeoHookean, simulate_truth(dir, kTruthNeoHookean)));
  FitProblem problem(s, {param("elastic.lambda"), param("elastic.mu"), param("viscous.nu")});
  const Eigen::VectorXd p = problem.map().initial();
  GradientOptions single, segmented;
  single.segment = s.time.end;
  single.checkpoint_steps = 20000;  // one segment with room for every step
  segmented.segment = 0.025;        // four segments
  const Evaluation a = problem.evaluate(p, single), b = problem.evaluate(p, segmented);
  ASSERT_TRUE(a.ok && b.ok) << a.error << b.error;
  EXPECT_EQ(b.experiments[0].segments, 4);
  EXPECT_LT((a.gradient - b.gradient).norm() / a.gradient.norm(), 1e-8)
      << a.gradient.transpose() << "\n"
      << b.gradient.transpose();
  EXPECT_NEAR(a.phi, b.phi, 1e-8 * a.phi);
  // Φ alone restarts at the same boundaries with the same first steps, so it
  // retraces the adjoint's trajectory step for step.
  GradientOptions phi_only = segmented;
  phi_only.method = GradientMethod::kNone;
  const Evaluation c = problem.evaluate(p, phi_only);
  ASSERT_TRUE(c.ok) << c.error;
  EXPECT_DOUBLE_EQ(c.phi, b.phi);
}

// Without a segment length, an experiment's first evaluation chooses one from its
// step count and keeps it: later evaluations at other parameters, and Φ alone,
// restart at the same times, so Φ stays one smooth function of the parameters.
TEST(Gradients, AutomaticSegmentsAreChosenOnceFromTheFirstRun) {
  const fs::path dir = scratch("auto-segments");
  const Scenario s =
      tight(fit_scenario(dir, kStartNeoHookean, simulate_truth(dir, kTruthNeoHookean)));
  const std::vector<FitParameterSpec> specs = {param("elastic.lambda"), param("elastic.mu"),
                                               param("viscous.nu")};
  FitProblem reference(s, specs);
  const Eigen::VectorXd p = reference.map().initial();
  GradientOptions roomy;
  roomy.checkpoint_steps = 20000;
  const Evaluation one = reference.evaluate(p, roomy);
  ASSERT_TRUE(one.ok) << one.error;
  ASSERT_EQ(one.experiments[0].segments, 1);
  const long steps = one.experiments[0].forward_stats.steps;

  // A budget of a third of the run: segments of at most a sixth of its steps.
  GradientOptions tight;
  tight.checkpoint_steps = steps / 3;
  FitProblem problem(s, specs);
  // The first adjoint pass measures λ's size, from which later ones set their
  // backward tolerances: a and b below must share them to agree exactly.
  ASSERT_TRUE(problem.evaluate(p, tight).ok);
  const Evaluation a = problem.evaluate(p, tight);
  ASSERT_TRUE(a.ok) << a.error;
  const int segments = a.experiments[0].segments;
  EXPECT_GE(segments, 6);
  EXPECT_LE(segments, 8);
  EXPECT_LT((a.gradient - one.gradient).norm() / one.gradient.norm(), 1e-8);

  // The same boundaries as an explicit segment length of T / segments.
  GradientOptions explicit_length;
  explicit_length.segment = s.time.end / segments;
  const Evaluation b = problem.evaluate(p, explicit_length);
  ASSERT_TRUE(b.ok) << b.error;
  EXPECT_EQ(b.experiments[0].segments, segments);
  EXPECT_EQ(a.phi, b.phi);
  EXPECT_EQ((a.gradient - b.gradient).norm(), 0.0);

  // Stiffer trial parameters take other steps but keep the plan.
  Eigen::VectorXd stiffer = p;
  stiffer.array() += std::log(1.5);  // log-transformed parameters
  GradientOptions phi_only = tight;
  phi_only.method = GradientMethod::kNone;
  const Evaluation c = problem.evaluate(stiffer, phi_only);
  ASSERT_TRUE(c.ok) << c.error;
  EXPECT_EQ(c.experiments[0].segments, segments);
  GradientOptions stiffer_explicit = explicit_length;
  stiffer_explicit.method = GradientMethod::kNone;
  EXPECT_EQ(problem.evaluate(stiffer, stiffer_explicit).phi, c.phi);
}

// One segment is one IDAS checkpoint interval. When a run needs more steps than
// the interval was given, it is integrated again with room for all of them, and
// the gradient is exactly the one of a run that had the room from the start; the
// first run does not count against a line-search trial's step limit.
TEST(Gradients, SegmentThatOutgrowsItsCheckpointBudgetIsRedoneExactly) {
  const fs::path dir = scratch("overrun");
  const Scenario s = fit_scenario(dir, kStartNeoHookean, simulate_truth(dir, kTruthNeoHookean));
  FitProblem problem(s, {param("elastic.lambda"), param("viscous.nu")});
  const Eigen::VectorXd p = problem.map().initial();
  GradientOptions roomy, cramped;
  roomy.segment = cramped.segment = s.time.end;  // explicitly one segment
  roomy.checkpoint_steps = 20000;
  ASSERT_TRUE(problem.evaluate(p, roomy).ok);  // sizes λ for the later passes' tolerances
  const Evaluation a = problem.evaluate(p, roomy);
  ASSERT_TRUE(a.ok) << a.error;
  const long steps = a.experiments[0].forward_stats.steps;
  cramped.checkpoint_steps = steps / 4;
  const Evaluation b = problem.evaluate(p, cramped);
  ASSERT_TRUE(b.ok) << b.error;
  EXPECT_GT(b.experiments[0].forward_stats.steps, steps + steps / 4);  // tries, then the redo
  EXPECT_EQ(b.experiments[0].backward_steps, a.experiments[0].backward_steps);
  EXPECT_EQ(a.phi, b.phi);
  EXPECT_EQ((a.gradient - b.gradient).norm(), 0.0);
  // A trial's step limit counts the redo, not the run it retraces.
  cramped.max_steps = steps + steps / 8;
  const Evaluation limited = problem.evaluate(p, cramped);
  EXPECT_TRUE(limited.ok) << limited.error;
  EXPECT_EQ(limited.phi, a.phi);
}

// The fit bounds each line-search trial's steps: past the limit the evaluation
// fails (and says where it stopped) instead of running on, for every method; the
// paced limit fails a run early that is on course to exceed it.
TEST(Gradients, StepLimitFailsTheEvaluationAndSaysWhere) {
  const fs::path dir = scratch("step-limit");
  const Scenario s = fit_scenario(dir, kStartNeoHookean, simulate_truth(dir, kTruthNeoHookean));
  FitProblem problem(s, {param("elastic.mu")});
  const Eigen::VectorXd p = problem.map().initial();
  for (GradientMethod method :
       {GradientMethod::kNone, GradientMethod::kForward, GradientMethod::kAdjoint}) {
    GradientOptions o;
    o.method = method;
    const Evaluation full = problem.evaluate(p, o);
    ASSERT_TRUE(full.ok) << full.error;
    const long steps = full.experiments[0].forward_stats.steps;
    o.max_steps = steps / 2;
    const Evaluation cut = problem.evaluate(p, o);
    EXPECT_FALSE(cut.ok) << to_string(method);
    EXPECT_NE(cut.error.find(fmt::format("more than {} integrator steps", steps / 2)),
              std::string::npos)
        << cut.error;
    EXPECT_GT(cut.experiments[0].t_reached, 0.0);
    EXPECT_LT(cut.experiments[0].t_reached, s.time.end);
    o.max_steps = steps;
    EXPECT_TRUE(problem.evaluate(p, o).ok) << to_string(method);

    // Paced: a run of no more steps than the reference passes a limit of k× its
    // steps paced with floor 1/k, whatever its profile in time ...
    for (int k : {2, 4}) {
      o.max_steps = k * steps;
      o.step_pace_floor = 1.0 / k;
      EXPECT_TRUE(problem.evaluate(p, o).ok) << to_string(method) << " k = " << k;
    }
    // ... and a run over the limit fails no later than unpaced, here earlier.
    o.max_steps = steps / 2;
    o.step_pace_floor = 0.05;
    const Evaluation paced = problem.evaluate(p, o);
    o.step_pace_floor = 1;
    EXPECT_FALSE(paced.ok) << to_string(method);
    EXPECT_NE(paced.error.find(fmt::format("{} over the whole run", steps / 2)), std::string::npos)
        << paced.error;
    EXPECT_LT(paced.experiments[0].t_reached, cut.experiments[0].t_reached) << to_string(method);
  }
}

// A run that the integrator itself stops (here its step limit, solver.max_steps)
// fails with the integrator's reason, for every method: reading Φ's quadrature
// after such a stop used to throw and replace it with "could not interpolate".
TEST(Gradients, IntegratorFailureKeepsItsOwnMessage) {
  const fs::path dir = scratch("solver-limit");
  Scenario s = fit_scenario(dir, kStartNeoHookean, simulate_truth(dir, kTruthNeoHookean));
  s.solver.max_steps = 300;  // the run takes a few thousand
  FitProblem problem(s, {param("elastic.mu")});
  for (GradientMethod method :
       {GradientMethod::kNone, GradientMethod::kForward, GradientMethod::kAdjoint}) {
    GradientOptions o;
    o.method = method;
    const Evaluation e = problem.evaluate(problem.map().initial(), o);
    EXPECT_FALSE(e.ok) << to_string(method);
    EXPECT_NE(e.error.find("solver.max_steps = 300"), std::string::npos)
        << to_string(method) << ": " << e.error;
  }
}

TEST(Gradients, OccludedMarkerDropsExactlyItsIntervals) {
  // With the tip hidden in frames 5..9, the tip contributes nothing on [t₄, t₁₀]
  // (the intervals that touch a hidden frame), and its track splits into two
  // independent splines: frames 0..4 and 10.. interpolate exactly as a capture
  // that ended at frame 4, or began at frame 10, would.
  const fs::path dir = scratch("occlusion");
  const std::string tracks = simulate_truth(dir, kTruthNeoHookean);
  // The tracks with the tip blanked in the rows where `hide` holds.
  const auto blank_tip = [&](const std::string& name, auto hide) {
    std::ifstream in(tracks);
    std::string line, out;
    for (int row = -1; std::getline(in, line); ++row) {
      if (row >= 0 && hide(row)) {
        // columns: t, tip_x, tip_y, tip_z, mid_...: blank the tip
        const auto c1 = line.find(',');
        std::string rest = line.substr(c1 + 1);
        for (int k = 0; k < 3; ++k) rest = rest.substr(rest.find(',') + 1);
        line = line.substr(0, c1) + ",,,," + rest;
      }
      out += line + "\n";
    }
    write(dir / name, out);
    return fit_scenario(dir, kStartNeoHookean, (dir / name).string());
  };
  const Scenario full = fit_scenario(dir, kStartNeoHookean, tracks);
  const Scenario hidden = blank_tip("occluded.csv", [](int row) { return row >= 5 && row <= 9; });
  const Scenario ended = blank_tip("ended.csv", [](int row) { return row >= 5; });
  const Scenario began = blank_tip("began.csv", [](int row) { return row <= 9; });
  const double dt = 1.0 / 200;
  GradientOptions none;
  none.method = GradientMethod::kNone;
  auto phi = [&](const Scenario& s, const std::string& marker, double t0, double t1) {
    ObjectiveSpec spec;  // marker "" = both
    if (!marker.empty()) spec.weights[marker == "tip" ? "mid" : "tip"] = 0;
    spec.window_begin = t0;
    spec.window_end = t1;
    FitProblem problem(s, {param("elastic.mu")});
    EvaluationPlan plan;
    ExperimentResult r =
        Experiment(s, spec).evaluate(problem.map(), problem.map().initial(), none, plan);
    EXPECT_TRUE(r.ok) << r.error;
    return r.phi;
  };
  // Only the mid marker is left there (equal up to the integration tolerance: the
  // quadrature's error control sees different components and steps differently).
  const double mid_only = phi(full, "mid", 4 * dt, 10 * dt);
  EXPECT_NEAR(phi(hidden, "", 4 * dt, 10 * dt), mid_only, 1e-6 * mid_only);
  EXPECT_GT(phi(full, "tip", 4 * dt, 10 * dt), 1e-3 * mid_only);
  for (auto [t0, t1, alone] : {std::tuple{0.0, 4 * dt, &ended}, std::tuple{10 * dt, 0.1, &began}}) {
    const double expected = phi(*alone, "tip", t0, t1);
    EXPECT_NEAR(phi(hidden, "tip", t0, t1), expected, 1e-6 * expected);
    // The gap does change the spline there: this is not the uninterrupted track.
    EXPECT_GT(std::abs(phi(full, "tip", t0, t1) - expected), 1e-5 * expected);
  }
  const double mid = phi(full, "mid", 0, 0.1);
  EXPECT_NEAR(phi(hidden, "mid", 0, 0.1), mid, 1e-6 * mid);
}

TEST(Gradients, OccludedBurstsKeepTheGradientExact) {
  // Both markers vanish in bursts (a fifth of the frames): the integrand jumps at
  // every burst edge, and adjoint, forward sensitivities and differences of Φ must
  // still agree, or a fit on occluded data would follow a wrong gradient.
  const fs::path dir = scratch("occluded-gradient");
  const std::string tracks = simulate_truth(dir, kTruthNeoHookean);
  std::ifstream in(tracks);
  std::string line, occluded;
  for (int row = -1; std::getline(in, line); ++row) {
    const bool tip_hidden = row >= 3 && row % 10 < 2,
               mid_hidden = row >= 3 && row % 10 >= 6 && row % 10 < 8;
    if (tip_hidden || mid_hidden) {
      std::vector<std::string> cells;
      std::stringstream ss(line);
      for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
      ASSERT_EQ(cells.size(), 7u);  // t, tip xyz, mid xyz
      for (int k = 0; k < 3; ++k) cells[(tip_hidden ? 1 : 4) + k].clear();
      line = cells[0];
      for (size_t k = 1; k < cells.size(); ++k) line += "," + cells[k];
    }
    occluded += line + "\n";
  }
  write(dir / "occluded.csv", occluded);
  const Scenario s = fit_scenario(dir, kStartNeoHookean, (dir / "occluded.csv").string());
  FitProblem problem(
      s, {param("elastic.lambda"), param("elastic.mu"), param("viscous.nu"), param("viscous.h")});
  expect_methods_agree(check_gradient(problem, problem.map().initial(), {}));
}

TEST(Gradients, CoarseToleranceAdjointPointsWhereForwardSensitivitiesDo) {
  // A fit's first stage runs at rtol 1e-3, near its minimum the misfit is small, and
  // λ scales with it. Backward tolerances guessed from the misfit were 4·10⁴× too
  // loose for λv on the benchmark bar: 102 backward steps for 2 s of 35 Hz
  // oscillation and a gradient with λ's and μ's signs flipped. Here, 1 s of the test
  // bar 5 % off the truth; forward sensitivities (whose error control covers the
  // sensitivities themselves) are the reference at the same tolerances.
  const fs::path dir = scratch("coarse-adjoint");
  test::ShakenBar truth;
  truth.material = kTruthNeoHookean.substr(1);
  truth.end = 1;
  truth.rtol = 1e-7;
  truth.atol = 1e-11;
  truth.tail = kMarkers;
  const std::string tracks = test::simulate_tracks(dir, "truth", test::shaken_bar_yaml(truth));
  test::ShakenBar fit = truth;
  fit.material = R"(  density: 1100
  elastic: { model: neo-hookean, lambda: 2.1e5, mu: 0.95e5 }
  viscous: { model: power-law, nu: 21, h: 0.84 })";
  fit.rtol = 1e-3;
  fit.atol = 1e-7;
  fit.tail = kMarkers.substr(0, kMarkers.rfind('\n')) + "\n  observed: " + tracks + "\n";
  write(dir / "fit.yaml", test::shaken_bar_yaml(fit));
  const Scenario s = load_scenario((dir / "fit.yaml").string());
  FitProblem problem(
      s, {param("elastic.lambda"), param("elastic.mu"), param("viscous.nu"), param("viscous.h")});
  const Eigen::VectorXd p = problem.map().initial();
  GradientOptions o;
  o.method = GradientMethod::kForward;
  const Evaluation forward = problem.evaluate(p, o);
  ASSERT_TRUE(forward.ok) << forward.error;
  o.method = GradientMethod::kAdjoint;
  // The first pass guesses λ's size; the second starts from the sizes the first met.
  for (int pass = 0; pass < 2; ++pass) {
    const Evaluation adjoint = problem.evaluate(p, o);
    ASSERT_TRUE(adjoint.ok) << adjoint.error;
    const Eigen::VectorXd &a = adjoint.gradient, &f = forward.gradient;
    EXPECT_GT(a.dot(f) / (a.norm() * f.norm()), 0.999) << "adjoint\n" << a << "\nforward\n" << f;
    for (int j = 0; j < a.size(); ++j)
      EXPECT_NEAR(a[j], f[j], 0.05 * std::abs(f[j])) << "parameter " << j << ", pass " << pass;
  }
}

}  // namespace
}  // namespace kelvin
