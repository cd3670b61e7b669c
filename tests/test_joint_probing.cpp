// Static probing measurements inside kelvin's fit (adjoint/static_term.hpp): the
// adjoint gradient of a static measurement's misfit against central differences,
// and a joint fit of the same specimen shaken (captured tracks) and probed (static
// marker positions) that recovers the truth from 2× off.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>

#include "adjoint/fit_problem.hpp"
#include "adjoint/uncertainty.hpp"
#include "base/error.hpp"
#include "fit/fit_loop.hpp"
#include "test_support.hpp"

namespace kelvin {
namespace {

using test::fs::path;

const std::string kTruth = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 6.0e5, mu: 3.0e5 }
  viscous: { model: newtonian, nu: 20 })";
const double kTrue[] = {6.0e5, 3.0e5, 20};
const std::string kStart = R"(
  density: 1100
  elastic: { model: neo-hookean, lambda: 1.2e6, mu: 1.5e5 }
  viscous: { model: newtonian, nu: 40 })";

/// The shaken bar of test_support.hpp (60 × 20 × 20 mm, clamped at x = 0) with
/// markers along it, shaken 4 and 3 mm at 17 and 13 Hz for 0.2 s (as test_fit's).
std::string shaken(const std::string& material, const std::string& tail) {
  test::ShakenBar bar;
  bar.name = "joint-bar";
  bar.material = material.substr(1);
  bar.amplitude_y = 0.004, bar.amplitude_z = 0.003;
  bar.end = 0.2, bar.output_rate = 1000;
  bar.rtol = 1e-7, bar.atol = 1e-11;
  bar.tail = test::kShakenBarMarkers + "\n" + tail;
  return test::shaken_bar_yaml(bar);
}

/// The same bar held at x = 0 and pressed at its free end: pushed down with 2 N and
/// pulled along its axis with 20 N (bending reads mostly μ, stretching E).
std::string probed(const std::string& material, const std::string& observed_dir) {
  auto observed = [&](const char* name) {
    return observed_dir.empty() ? std::string()
                                : ", observed: " + observed_dir + "/" + name + ".csv";
  };
  return "name: joint-bar-probed\n"
         "mesh: { generate: box, lo: [0, 0, 0], hi: [0.06, 0.02, 0.02], element_size: 0.01 }\n"
         "material:\n" +
         material.substr(1) +
         "\nclamps: [{ name: base, select: { plane: { axis: x, at: 0 } } }]\n"
         "markers:\n  rest:\n"
         "    - { name: tip, at: [0.06, 0.01, 0.01] }\n"
         "    - { name: mid, at: [0.03, 0.01, 0.02] }\n"
         "    - { name: top, at: [0.045, 0.01, 0.02] }\n"
         "    - { name: side, at: [0.05, 0.0, 0.01] }\n"
         "probing:\n  measurements:\n"
         "    - { name: bend, loads: [{ name: p, select: { plane: { axis: x, at: 0.06 } }, "
         "force: [0, 0, -2] }]" +
         observed("bend") +
         " }\n"
         "    - { name: stretch, loads: [{ name: p, select: { plane: { axis: x, at: 0.06 } }, "
         "force: [20, 0, 0] }]" +
         observed("stretch") + " }\n";
}

/// Writes the truth's tracks and static positions under dir; returns the tracks' path.
std::string make_data(const path& dir) {
  const std::string tracks = test::simulate_tracks(dir, "truth-shaken", shaken(kTruth, ""));
  test::write_text(dir / "truth-probed.yaml", probed(kTruth, ""));
  const test::CliRun r = test::run_kelvin("probe " + (dir / "truth-probed.yaml").string() + " -o " +
                                          (dir / "static").string());
  if (r.exit_code != 0) throw std::runtime_error(r.out);
  return tracks;
}

TEST(JointProbing, TheStaticTermsAdjointGradientMatchesCentralDifferences) {
  const path dir = test::scratch("joint-gradient");
  const std::string tracks = make_data(dir);
  test::write_text(dir / "probed.yaml", probed(kStart, (dir / "static").string()));
  test::write_text(dir / "fit.yaml",
                   shaken(kStart, "  observed: " + tracks +
                                      "\nfit:\n  parameters: [elastic.lambda, elastic.mu, "
                                      "viscous.nu]\n  experiments: [probed.yaml]\n"));
  const Scenario s = load_scenario((dir / "fit.yaml").string());
  FitProblem problem(s, s.fit.parameters);
  ASSERT_EQ(problem.num_experiments(), 1);
  ASSERT_EQ(problem.num_static_terms(), 2);
  const Eigen::VectorXd p = problem.map().initial();
  for (int k = 0; k < 2; ++k) {
    StaticTerm& term = problem.static_term(k);
    EXPECT_EQ(term.weight(), 0.2);  // the fitted scenario's duration
    const StaticTermResult at = term.evaluate(problem.map(), p, true);
    ASSERT_TRUE(at.ok) << at.error;
    EXPECT_GT(at.rms, 1e-5) << term.name();  // 2× off: the markers are far off
    for (int j = 0; j < p.size(); ++j) {
      const double h = 1e-5;
      Eigen::VectorXd up = p, down = p;
      up[j] += h, down[j] -= h;
      const double fd = (term.evaluate(problem.map(), up, false).phi -
                         term.evaluate(problem.map(), down, false).phi) /
                        (2 * h);
      const double scale = at.gradient.cwiseAbs().maxCoeff();
      EXPECT_NEAR(at.gradient[j], fd, 1e-6 * scale) << term.name() << " " << problem.map().label(j);
    }
    // The viscosity carries no static load.
    EXPECT_EQ(at.gradient[2], 0.0) << term.name();
  }
}

TEST(JointProbing, TheStaticResidualsJacobianMatchesCentralDifferences) {
  // The Gauss–Newton rows of a static measurement (standard errors, scaled starts).
  const path dir = test::scratch("joint-jacobian");
  const std::string tracks = make_data(dir);
  test::write_text(dir / "probed.yaml", probed(kStart, (dir / "static").string()));
  test::write_text(dir / "fit.yaml",
                   shaken(kStart, "  observed: " + tracks +
                                      "\nfit:\n  parameters: [elastic.lambda, elastic.mu, "
                                      "viscous.nu]\n  experiments: [probed.yaml]\n"));
  const Scenario s = load_scenario((dir / "fit.yaml").string());
  FitProblem problem(s, s.fit.parameters);
  const Eigen::VectorXd p = problem.map().initial();
  StaticTerm& term = problem.static_term(0);
  Eigen::VectorXd r, up, down;
  Eigen::MatrixXd J, unused;
  std::vector<std::pair<int, int>> where;
  std::string error;
  ASSERT_TRUE(term.residuals(problem.map(), p, true, r, J, where, error)) << error;
  ASSERT_EQ(r.size(), 12);  // 4 markers × 3 axes
  ASSERT_EQ(J.rows(), 12);
  // Φ_s is w/2 ‖r‖².
  EXPECT_NEAR(0.5 * term.weight() * r.squaredNorm(), term.evaluate(problem.map(), p, false).phi,
              1e-12 * r.squaredNorm());
  for (int j = 0; j < p.size(); ++j) {
    const double h = 1e-5;
    Eigen::VectorXd pu = p, pd = p;
    pu[j] += h, pd[j] -= h;
    ASSERT_TRUE(term.residuals(problem.map(), pu, false, up, unused, where, error));
    ASSERT_TRUE(term.residuals(problem.map(), pd, false, down, unused, where, error));
    const Eigen::VectorXd fd = (up - down) / (2 * h);
    EXPECT_LT((J.col(j) - fd).norm(), 1e-6 * J.norm() + 1e-15) << problem.map().label(j);
  }
  // The system the standard errors come from holds the captured frames and then the
  // static coordinates, marked by their measurement.
  const GaussNewtonSystem g = gauss_newton_system(problem, p);
  ASSERT_TRUE(g.ok) << g.error;
  int statics = 0;
  for (const auto& sample : g.samples) statics += sample.experiment < 0;
  EXPECT_EQ(statics, 24);
  EXPECT_EQ(g.samples.back().experiment, -2);
}

TEST(JointProbing, ShakenAndProbedTogetherRecoverTheTruthFromTwiceOff) {
  const path dir = test::scratch("joint-fit");
  const std::string tracks = make_data(dir);
  test::write_text(dir / "probed.yaml", probed(kStart, (dir / "static").string()));
  test::write_text(dir / "fit.yaml",
                   shaken(kStart, "  observed: " + tracks +
                                      "\nfit:\n  parameters: [elastic.lambda, elastic.mu, "
                                      "viscous.nu]\n  experiments: [probed.yaml]\n"
                                      "  ftol_rel: 1.0e-14\n  xtol_rel: 1.0e-9\n"));
  const Scenario s = load_scenario((dir / "fit.yaml").string());
  FitProblem problem(s, s.fit.parameters);
  FitOptions o;
  o.max_evaluations = 80;
  o.ftol_rel = 1e-14, o.xtol_rel = 1e-9;
  const FitOutcome out = run_fit(problem, problem.map().initial(), o);
  EXPECT_LT(out.best.rms, 1e-6);  // metres: the truth is in the model class
  for (int j = 0; j < 3; ++j)
    EXPECT_NEAR(problem.map().value(out.p, j) / kTrue[j], 1.0, 1e-3)
        << problem.map().label(j) << " after " << out.evaluations << " (" << out.stop_reason << ")";
  GradientOptions none;
  none.method = GradientMethod::kNone;
  const Evaluation ev = problem.evaluate(out.p, none);
  ASSERT_TRUE(ev.ok) << ev.error;
  ASSERT_EQ(ev.statics.size(), 2u);
  for (const auto& r : ev.statics) EXPECT_LT(r.rms, 1e-6);  // kelvin probe writes 9 digits
}

TEST(JointProbing, MeasurementsWithoutObservedPositionsStayOutOfTheFit) {
  // A probing section kept for kelvin probe's predictions changes nothing in a fit
  // of captured tracks; alone, with nothing observed, there is nothing to fit.
  const path dir = test::scratch("joint-unobserved");
  const std::string tracks = make_data(dir);
  const std::string probing = probed(kStart, "");
  const std::string section = probing.substr(probing.find("probing:"));
  test::write_text(dir / "fit.yaml", shaken(kStart, "  observed: " + tracks + "\n" + section +
                                                        "fit:\n  parameters: [elastic.mu]\n"));
  const Scenario s = load_scenario((dir / "fit.yaml").string());
  FitProblem problem(s, s.fit.parameters);
  EXPECT_EQ(problem.num_experiments(), 1);
  EXPECT_EQ(problem.num_static_terms(), 0);

  test::write_text(dir / "alone.yaml", probing + "fit:\n  parameters: [elastic.mu]\n");
  const Scenario alone = load_scenario((dir / "alone.yaml").string());
  try {
    FitProblem nothing(alone, alone.fit.parameters);
    FAIL() << "accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("nothing to fit"), std::string::npos) << e.what();
  }
}

TEST(JointProbing, AStaticMeasurementOfAnotherMaterialIsRefusedWithItsName) {
  const path dir = test::scratch("joint-refused");
  const std::string tracks = make_data(dir);
  const std::string other = R"(
  density: 1100
  elastic: { model: stvk, lambda: 6.0e5, mu: 3.0e5 }
  viscous: { model: newtonian, nu: 20 })";
  test::write_text(dir / "probed.yaml", probed(other, (dir / "static").string()));
  test::write_text(dir / "fit.yaml",
                   shaken(kStart, "  observed: " + tracks +
                                      "\nfit:\n  parameters: [elastic.lambda, elastic.mu]\n"
                                      "  experiments: [probed.yaml]\n"));
  const Scenario s = load_scenario((dir / "fit.yaml").string());
  try {
    FitProblem problem(s, s.fit.parameters);
    FAIL() << "accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("static measurement 'bend' has other material models"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace kelvin

namespace kelvin {
namespace {

TEST(ProbingFitCli, StaticMeasurementsAloneFitThroughKelvinFitWithStandardErrors) {
  // The probing example through kelvin fit's loop: the same optimum as probe-fit
  // (λ 22.2 kPa, μ 11.2 kPa), standard errors from the static rows of the
  // Gauss–Newton system, the noise read back, and a fitted scenario kelvin probe runs.
  const path out = test::scratch("probing-fit-cli");
  test::CliRun r = test::run_kelvin(
      "fit " KELVIN_SOURCE_DIR "/yaml/examples/probe-foam-block.yaml -q -o " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const std::string fitted = test::read_text(out / "fitted.yaml");
  double lambda = 0, mu = 0;
  const auto at = fitted.find("lambda:");
  ASSERT_NE(at, std::string::npos) << fitted;
  ASSERT_EQ(std::sscanf(fitted.c_str() + at, "lambda: %lf, mu: %lf", &lambda, &mu), 2) << fitted;
  EXPECT_NEAR(lambda, 22186, 30);
  EXPECT_NEAR(mu, 11238, 10);
  const std::string report = test::read_text(out / "report.md");
  EXPECT_NE(report.find("| elastic.lambda | 4e+04 | 2.219e+04 | ± "), std::string::npos) << report;
  EXPECT_NE(report.find("| elastic.mu | 5000 | 1.124e+04 | ± "), std::string::npos) << report;
  double sigma = 0;
  const auto noise = report.find("Estimated marker noise σ = ");
  ASSERT_NE(noise, std::string::npos) << report;
  ASSERT_EQ(std::sscanf(report.c_str() + noise + std::strlen("Estimated marker noise σ = "), "%lf",
                        &sigma),
            1);
  EXPECT_NEAR(sigma, 0.05, 0.005);  // mm: the example's noise
  r = test::run_kelvin("probe " + (out / "fitted.yaml").string() + " -o " + (out / "sim").string());
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_TRUE(test::fs::exists(out / "sim" / "corner.csv"));
}

}  // namespace
}  // namespace kelvin
