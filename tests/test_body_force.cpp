// A fitted body-force field (engine/body_force.hpp): its gradient agrees three ways,
// a field that made the tracks is recovered from zero, it adds nothing to a fit's
// fitted.yaml, and the scenario refuses what has no meaning.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "adjoint/fit_problem.hpp"
#include "adjoint/marker_trajectory.hpp"
#include "base/error.hpp"
#include "engine/csv.hpp"
#include "fit/fit_loop.hpp"
#include "gradient_agreement.hpp"
#include "test_support.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;

test::ShakenBar shaken_bar(const std::string& tail) {
  test::ShakenBar b;
  b.material =
      "  density: 1100\n  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }\n"
      "  viscous: { model: newtonian, nu: 20 }";
  b.tail = test::kShakenBarMarkers + tail;
  return b;
}

/// The shaken bar observing `tracks`, fitting `parameters` (a YAML list body).
Scenario observing(const fs::path& dir, const std::string& name, const std::string& tracks,
                   const std::string& parameters) {
  const test::ShakenBar b =
      shaken_bar("\n  observed: " + tracks + "\nfit:\n  parameters:\n" + parameters);
  test::write_text(dir / (name + ".yaml"), test::shaken_bar_yaml(b));
  return load_scenario((dir / (name + ".yaml")).string());
}

std::string refusal(const fs::path& dir, const std::string& parameters) {
  try {
    observing(dir, "bad", (dir / "truth" / "markers.csv").string(), parameters);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(BodyForce, TheGradientOfAFieldInBoxesAndTimeAgreesThreeWays) {
  const fs::path dir = test::scratch("body-force-gradient");
  const std::string tracks =
      test::simulate_tracks(dir, "truth", test::shaken_bar_yaml(shaken_bar("")));
  // Off the truth (μ 20 % high) so that the gradient is not the noise of a minimum.
  const Scenario s = observing(dir, "fit", tracks, R"(
    - { target: elastic.mu, initial: 1.2e5 }
    - { target: body_force.y, knots: 3, initial: 0.5,
        scope: { boxes: [ { min: [0, 0, 0], max: [0.03, 0.02, 0.02] } ] } }
    - { target: body_force.z, knots: 3, initial: -0.3 })");
  FitProblem problem(s, s.fit.parameters);
  ASSERT_EQ(problem.map().size(), 1 + 2 * 3 + 3);
  EXPECT_EQ(problem.map().label(1), "body_force.y[box 0][t 0.025 s]");
  test::expect_gradients_agree(problem);
}

TEST(BodyForce, AFieldThatMadeTheTracksIsRecoveredFromZero) {
  const fs::path dir = test::scratch("body-force-recovery");
  const std::string nominal =
      test::simulate_tracks(dir, "truth", test::shaken_bar_yaml(shaken_bar("")));
  const std::string parameters = R"(
    - { target: body_force.y, knots: 4 }
    - { target: body_force.z, knots: 4 })";
  // The truth: the nominal bar pushed by a known force history, sampled as a capture.
  const Scenario made = observing(dir, "made", nominal, parameters);
  FitProblem truth(made, made.fit.parameters);
  Eigen::VectorXd p_true(8);
  p_true << 0.8, -1.5, 1.2, 0.4, -0.6, 0.9, 0.3, -1.1;  // m/s² at 0.02 … 0.08 s
  const MarkerTracks frames = read_marker_tracks(nominal);
  const MarkerTrajectory tr = simulate_markers(truth, 0, p_true, frames.times, false);
  ASSERT_TRUE(tr.ok) << tr.error;
  std::string csv = "t";
  for (const auto& n : frames.names) csv += "," + n + "_x," + n + "_y," + n + "_z";
  csv += "\n";
  for (size_t k = 0; k < tr.times.size(); ++k) {
    csv += fmt::format("{:.12g}", tr.times[k]);
    for (long m = 0; m < tr.positions[k].cols(); ++m)
      for (int i = 0; i < 3; ++i) csv += fmt::format(",{:.12g}", tr.positions[k](i, m));
    csv += "\n";
  }
  test::write_text(dir / "pushed.csv", csv);
  // The pushed tracks differ from the nominal ones by far more than the recovery's
  // tolerance, so recovering p_true is not recovering 0.
  const MarkerTracks pushed = read_marker_tracks((dir / "pushed.csv").string());
  EXPECT_GT((pushed.xyz - frames.xyz).cwiseAbs().maxCoeff(), 1e-5);

  const Scenario s = observing(dir, "fit", (dir / "pushed.csv").string(), parameters);
  FitProblem problem(s, s.fit.parameters);
  FitOptions o;
  o.max_evaluations = 60;
  const FitOutcome out = run_fit(problem, problem.map().initial(), o);
  ASSERT_GT(out.evaluations, 0);
  for (int j = 0; j < 8; ++j)
    EXPECT_NEAR(out.p[j], p_true[j], 0.02 * p_true.cwiseAbs().maxCoeff())
        << problem.map().label(j) << ": " << out.stop_reason << " after " << out.evaluations
        << " evaluations";
}

TEST(BodyForce, AtZeroTheFieldReproducesTheNominalModelExactly) {
  const fs::path dir = test::scratch("body-force-nominal");
  const std::string tracks =
      test::simulate_tracks(dir, "truth", test::shaken_bar_yaml(shaken_bar("")));
  const Scenario s = observing(dir, "fit", tracks, "    - { target: elastic.mu }\n");
  const Scenario f =
      observing(dir, "force", tracks,
                "    - { target: elastic.mu }\n    - { target: body_force.x, knots: 5 }\n");
  FitProblem plain(s, s.fit.parameters), forced(f, f.fit.parameters);
  GradientOptions g;
  g.method = GradientMethod::kNone;
  const Evaluation a = plain.evaluate(plain.map().initial(), g);
  const Evaluation b = forced.evaluate(forced.map().initial(), g);
  ASSERT_TRUE(a.ok && b.ok) << a.error << b.error;
  EXPECT_EQ(a.phi, b.phi);  // the same steps: the field's load is exactly zero
}

TEST(BodyForce, TheScenarioRefusesWhatHasNoMeaning) {
  const fs::path dir = test::scratch("body-force-refusals");
  test::simulate_tracks(dir, "truth", test::shaken_bar_yaml(shaken_bar("")));
  EXPECT_NE(refusal(dir, "    - { target: body_force.x }").find("needs 'knots'"),
            std::string::npos);
  EXPECT_NE(refusal(dir, "    - { target: elastic.mu, knots: 3 }").find("knots are the time basis"),
            std::string::npos);
  EXPECT_NE(refusal(dir, "    - { target: body_force.y, knots: 2.5 }").find("whole number"),
            std::string::npos);
  EXPECT_NE(refusal(dir,
                    "    - { target: body_force.y, knots: 2 }\n"
                    "    - { target: body_force.z, knots: 3 }")
                .find("one field, one time basis"),
            std::string::npos);
  EXPECT_NE(
      refusal(
          dir,
          "    - { target: body_force.y, knots: 2, scope: { legendre: { axis: x, degree: 2 } } }")
          .find("is a value field"),
      std::string::npos);
  EXPECT_NE(refusal(dir, "    - { target: elastic.mu, penalty: 1.0 }").find("Gaussian prior"),
            std::string::npos);
  const std::string bad = refusal(dir, "    - body_force.w");
  EXPECT_NE(bad.find("bad.yaml:"), std::string::npos) << bad;
  EXPECT_NE(bad.find("body_force.x"), std::string::npos) << bad;  // the fittable list names it
}

}  // namespace kelvin
