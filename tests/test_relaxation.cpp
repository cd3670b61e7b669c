// A relaxing branch (materials/maxwell.hpp): its six internal variables per element
// join the integrated state. Nested at zero modulus (steps exactly as the model
// without it), an added St. Venant–Kirchhoff term when it never relaxes, a
// viscosity gτ when it relaxes at once; its gradients agree three ways through
// the internal variables' own sensitivities and adjoint, and a fit finds it.
#include <gtest/gtest.h>

#include <string>

#include "adjoint/fit_problem.hpp"
#include "fit/fit_loop.hpp"
#include "gradient_agreement.hpp"
#include "materials/derivative_check.hpp"
#include "test_support.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;

/// The shaken bar with `material`, observing `tracks` when given, fitting `fit`.
std::string bar(const std::string& material, const std::string& initial = "static",
                const std::string& tracks = "", double end = 0.1, const std::string& fit = "") {
  test::ShakenBar b;
  b.material = material;
  b.end = end;
  b.tail = test::kShakenBarMarkers + (tracks.empty() ? "" : "\n  observed: " + tracks) + "\n" + fit;
  std::string yaml = test::shaken_bar_yaml(b);
  const std::string key = "initial: static";
  yaml.replace(yaml.find(key), key.size(), "initial: " + initial);
  return yaml;
}

std::string with_branch(const std::string& branch,
                        const std::string& viscous = "newtonian, nu: 20") {
  return fmt::format(R"(  density: 1100
  elastic:
    - {{ model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }}
    - {{ model: maxwell, {} }}
  viscous: {{ model: {} }})",
                     branch, viscous);
}

/// Largest difference between two track files, and the largest excursion of the
/// first from its start (m).
std::pair<double, double> track_difference(const std::string& a, const std::string& b) {
  const MarkerTracks ta = read_marker_tracks(a), tb = read_marker_tracks(b);
  EXPECT_EQ(ta.xyz.cols(), tb.xyz.cols());
  const double diff = (ta.xyz - tb.xyz).cwiseAbs().maxCoeff();
  const double motion = (ta.xyz.colwise() - ta.xyz.col(0)).cwiseAbs().maxCoeff();
  return {diff, motion};
}

/// Φ in one segment: the automatic segment plan sizes segments by the memory of a
/// stored step, which the internal variables enlarge.
Evaluation phi(FitProblem& problem) {
  GradientOptions o;
  o.method = GradientMethod::kNone;
  o.segment = 1;
  return problem.evaluate(problem.map().initial(), o);
}

}  // namespace

TEST(Relaxation, AtZeroModulusItStepsExactlyAsTheNominalModel) {
  const fs::path dir = test::scratch("relaxation-nominal");
  const std::string tracks =
      test::simulate_tracks(dir, "truth", bar(with_branch("g: 4.0e4, tau: 0.01")));
  test::write_text(dir / "nominal.yaml", bar(R"(  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
  viscous: { model: newtonian, nu: 20 })",
                                             "static", tracks));
  test::write_text(dir / "nested.yaml", bar(with_branch("g: 0, tau: 0.01"), "static", tracks));
  const Scenario s_nominal = load_scenario((dir / "nominal.yaml").string());
  const Scenario s_nested = load_scenario((dir / "nested.yaml").string());
  FitProblem nominal(s_nominal, {positive_fit_parameter("elastic.mu")});
  FitProblem nested(s_nested, {positive_fit_parameter("elastic.mu")});
  const Evaluation a = phi(nominal), b = phi(nested);
  ASSERT_TRUE(a.ok) << a.error;
  ASSERT_TRUE(b.ok) << b.error;
  // Its variables (6 per element) are integrated but weigh nothing in the
  // error test while they cannot move the body.
  EXPECT_EQ(b.experiments[0].forward_stats.steps, a.experiments[0].forward_stats.steps);
  EXPECT_EQ(b.phi, a.phi);
  EXPECT_GT(a.phi, 0);
}

TEST(Relaxation, ANeverRelaxingBranchIsAStVenantKirchhoffTerm) {
  // From rest Z = 0, and with τ ≫ the run Z stays 0: S = 2gE, St. Venant–Kirchhoff
  // with λ = 0. The branch relaxes by t/τ = 1e-7 of its stress within the run.
  const fs::path dir = test::scratch("relaxation-elastic-limit");
  const std::string branch =
      test::simulate_tracks(dir, "branch", bar(with_branch("g: 5.0e4, tau: 1.0e6"), "rest"));
  const std::string svk = test::simulate_tracks(dir, "svk",
                                                bar(R"(  density: 1100
  elastic:
    - { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
    - { model: stvk, lambda: 1.0e-9, mu: 5.0e4 }
  viscous: { model: newtonian, nu: 20 })",
                                                    "rest"));
  const std::string plain =
      test::simulate_tracks(dir, "plain", bar(with_branch("g: 0, tau: 1.0e6"), "rest"));
  const auto [diff, motion] = track_difference(branch, svk);
  const auto [effect, unused] = track_difference(branch, plain);
  EXPECT_GT(effect, 1e-4);  // the branch stiffens the bar visibly: a tenth of a mm and more
  EXPECT_LT(diff, 1e-5 * effect) << "motion " << motion << " m, branch effect " << effect << " m";
}

TEST(Relaxation, AFastRelaxingBranchDampsLikeAViscosity) {
  // τ ≪ the motion's period: Z = E − τĖ + O(τ²), so S = 2gτ Ė, the stress of a
  // Newtonian viscosity ν = gτ to first order in the strain (newtonian is
  // ν J (L + Lᵀ) F⁻ᵀ; F (2ν Ė) differs from it by O(|F − I|)). The bars are nearly
  // undamped but for it (ν = 1e-9 Pa s: the viscous list cannot be empty).
  const fs::path dir = test::scratch("relaxation-viscous-limit");
  const double g = 2.0e5, tau = 1e-4;  // ν = gτ = 20 Pa s, τ·2π·17 Hz ≈ 0.01
  const std::string branch = test::simulate_tracks(
      dir, "branch",
      bar(with_branch(fmt::format("g: {}, tau: {}", g, tau), "newtonian, nu: 1.0e-9")));
  const std::string viscous = test::simulate_tracks(
      dir, "viscous", bar(with_branch("g: 0, tau: 1", fmt::format("newtonian, nu: {}", g * tau))));
  const std::string undamped = test::simulate_tracks(
      dir, "undamped", bar(with_branch("g: 0, tau: 1", "newtonian, nu: 1.0e-9")));
  const auto [diff, motion] = track_difference(branch, viscous);
  const auto [effect, unused] = track_difference(viscous, undamped);
  EXPECT_GT(effect, 1e-4);
  EXPECT_LT(diff, 0.05 * effect) << "damping's effect " << effect << " m";
}

TEST(Relaxation, GradientsAgreeThreeWaysAwayFromAndAtZeroModulus) {
  const fs::path dir = test::scratch("relaxation-gradients");
  const std::string tracks =
      test::simulate_tracks(dir, "truth", bar(with_branch("g: 8.0e4, tau: 0.01")));
  const std::string fit = R"(fit:
  parameters:
    - { target: elastic.g, lower: 0 }
    - { target: elastic.tau, log: true }
    - { target: elastic.mu, log: true })";
  for (const std::string branch : {"g: 5.0e4, tau: 0.02", "g: 0, tau: 0.02"}) {
    SCOPED_TRACE(branch);
    test::write_text(dir / "fit.yaml", bar(with_branch(branch), "static", tracks, 0.1, fit));
    const Scenario s = load_scenario((dir / "fit.yaml").string());
    FitProblem problem(s, s.fit.parameters);
    test::expect_gradients_agree(problem);
  }
}

TEST(Relaxation, TheFitFindsTheBranchFromZeroModulus) {
  const fs::path dir = test::scratch("relaxation-recovery");
  const std::string tracks = test::simulate_tracks(
      dir, "truth", bar(with_branch("g: 6.0e4, tau: 0.01"), "static", "", 0.15));
  const std::string fit = R"(fit:
  parameters:
    - { target: elastic.g, lower: 0, upper: 1.0e6 }
    - { target: elastic.tau, log: true, lower: 1.0e-4, upper: 1 })";
  test::write_text(dir / "fit.yaml",
                   bar(with_branch("g: 0, tau: 0.03"), "static", tracks, 0.15, fit));
  const Scenario s = load_scenario((dir / "fit.yaml").string());
  FitProblem problem(s, s.fit.parameters);
  FitOptions o = fit_options_of(s);  // as kelvin fit runs it: staged tolerances
  o.max_evaluations = 40;
  const FitOutcome out = run_fit(problem, problem.map().initial(), o);
  EXPECT_NEAR(problem.map().value(out.p, 0), 6.0e4, 0.02 * 6.0e4) << out.stop_reason;
  EXPECT_NEAR(problem.map().value(out.p, 1), 0.01, 0.02 * 0.01) << out.stop_reason;
}

TEST(Relaxation, APluginWithInternalVariablesIntegratesAsTheBuiltInOne) {
  // The same branch through the plugin ABI (tests/plugins/relaxing.cpp): the same
  // trajectory, misfit and adjoint gradient to the last bit.
  const fs::path dir = test::scratch("relaxation-plugin");
  const std::string tracks =
      test::simulate_tracks(dir, "truth", bar(with_branch("g: 8.0e4, tau: 0.01")));
  const std::string fit = R"(fit:
  parameters:
    - { target: elastic.g, lower: 0 }
    - { target: elastic.tau, log: true })";
  test::write_text(dir / "builtin.yaml",
                   bar(with_branch("g: 5.0e4, tau: 0.02"), "static", tracks, 0.1, fit));
  test::write_text(
      dir / "plugin.yaml",
      bar(with_branch(fmt::format("g: 5.0e4, tau: 0.02, plugin: {}", KELVIN_RELAXING_PLUGIN)),
          "static", tracks, 0.1, fit));
  GradientOptions o;
  o.method = GradientMethod::kAdjoint;
  o.segment = 1;
  Eigen::VectorXd g[2];
  double phi[2];
  int k = 0;
  for (const char* name : {"builtin.yaml", "plugin.yaml"}) {
    const Scenario s = load_scenario((dir / name).string());
    FitProblem problem(s, s.fit.parameters);
    const Evaluation e = problem.evaluate(problem.map().initial(), o);
    ASSERT_TRUE(e.ok) << name << ": " << e.error;
    phi[k] = e.phi;
    g[k++] = e.gradient;
  }
  EXPECT_EQ(phi[1], phi[0]);
  EXPECT_EQ(g[1], g[0]);
  EXPECT_GT(g[0].norm(), 0);
}

TEST(Relaxation, APluginsEvolutionLawPassesTheDerivativeCheckThroughTheAbi) {
  // What `kelvin check-material plugin.so` runs: the evolution law and ∂P/∂z cross
  // the C ABI intact.
  auto m = create_material("maxwell", KELVIN_RELAXING_PLUGIN);
  ASSERT_EQ(m->internal_size(), 6);
  const auto checks = check_material_derivatives(*m, {4e4, 0.05});
  int evolution = 0;
  for (const auto& c : checks) {
    EXPECT_TRUE(c.passed()) << c.what << " at " << c.state << " relative error " << c.error;
    evolution += c.what.rfind("df/", 0) == 0;
  }
  EXPECT_EQ(evolution, 3 * 8);
}

}  // namespace kelvin
