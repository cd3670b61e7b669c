// The stiffness scan before a fit (fit/stiffness_scan.hpp): it scales only the
// fitted elastic moduli, finds the grid point nearest the truth's scale, and a fit
// started there recovers the truth.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>

#include "adjoint/fit_problem.hpp"
#include "fit/fit_loop.hpp"
#include "fit/stiffness_scan.hpp"
#include "test_support.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;

std::string material(double lambda, double mu) {
  return fmt::format(
      "  density: 1100\n  elastic: {{ model: neo-hookean, lambda: {}, mu: {} }}\n"
      "  viscous: {{ model: newtonian, nu: 5 }}",
      lambda, mu);
}

}  // namespace

TEST(StiffnessScan, FindsTheTruthsScaleAndAFitFromThereRecoversIt) {
  const fs::path dir = test::scratch("stiffness-scan");
  test::ShakenBar b;
  b.end = 0.3;
  b.material = material(8e4, 4e4);
  b.tail = test::kShakenBarMarkers;
  const std::string tracks = test::simulate_tracks(dir, "truth", test::shaken_bar_yaml(b));

  // The user's guess is 2.5× too stiff: the truth sits at ×0.4 of it, between the
  // grid's ×0.41 (1.25⁻⁴) and the half steps ×0.366 and ×0.458 beside it.
  b.material = material(2e5, 1e5);
  b.rtol = 1e-7;
  b.atol = 1e-11;
  b.tail = test::kShakenBarMarkers + "\n  observed: " + tracks +
           "\nfit:\n  parameters: [elastic.lambda, elastic.mu, viscous.nu]\n";
  test::write_text(dir / "guess.yaml", test::shaken_bar_yaml(b));
  const Scenario s = load_scenario((dir / "guess.yaml").string());
  FitProblem problem(s, s.fit.parameters);
  const ParameterMap& map = problem.map();

  const std::vector<int> moduli = modulus_entries(problem);
  ASSERT_EQ(moduli.size(), 2u);  // λ and μ, not ν (Pa s)
  EXPECT_EQ(map.label(moduli[0]), "elastic.lambda");
  EXPECT_EQ(map.label(moduli[1]), "elastic.mu");

  const FitOptions options = fit_options_of(s);
  const StiffnessScan scan = scan_stiffness(problem, map.initial(), options);
  ASSERT_EQ(scan.points.size(), 17u);  // 15 grid points and two half steps
  EXPECT_NEAR(scan.scale, std::pow(1.25, -4), 1e-12);
  EXPECT_NEAR(map.value(scan.p, moduli[1]), 1e5 * scan.scale, 1e-6);
  EXPECT_NEAR(map.value(scan.p, 2), 5.0, 1e-9);  // ν untouched
  double at_start = 0, at_best = 0;
  for (const auto& p : scan.points) {
    ASSERT_TRUE(p.ok) << "×" << p.scale << ": " << p.error;
    if (p.scale == 1) at_start = p.rms;
    if (p.scale == scan.scale) at_best = p.rms;
  }
  // 2.4 % off the truth's moduli against 150 %: the misfit falls tenfold and more.
  EXPECT_LT(at_best, 0.1 * at_start);

  FitOptions f = options;
  f.max_evaluations = 60;
  const FitOutcome out = run_fit(problem, scan.p, f);
  EXPECT_NEAR(map.value(out.p, moduli[1]) / 4e4, 1, 0.01);
  EXPECT_NEAR(map.value(out.p, moduli[0]) / 8e4, 1, 0.05);
  EXPECT_NEAR(map.value(out.p, 2) / 5, 1, 0.05);
}

TEST(StiffnessScan, AScanKeyOtherThanStiffnessOrNoneIsRefusedWithItsPlace) {
  const fs::path dir = test::scratch("stiffness-scan-key");
  test::ShakenBar b;
  b.material = material(8e4, 4e4);
  b.tail = test::kShakenBarMarkers + "\nfit:\n  parameters: [elastic.mu]\n  start_scan: grid\n";
  test::write_text(dir / "bad.yaml", test::shaken_bar_yaml(b));
  try {
    load_scenario((dir / "bad.yaml").string());
    FAIL() << "accepted start_scan: grid";
  } catch (const std::exception& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("fit.start_scan"), std::string::npos) << what;
    EXPECT_NE(what.find("stiffness"), std::string::npos) << what;
  }
}

}  // namespace kelvin
