// The objective's terms in the parameters alone: their values in closed form and
// their gradients against central differences.
#include <gtest/gtest.h>

#include <filesystem>

#include "adjoint/fit_problem.hpp"
#include "adjoint/parameter_terms.hpp"
#include "materials/spline_material.hpp"
#include "test_support.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;

/// The shaken bar (144 tets) of a spline material (its defaults: neo-Hookean,
/// λ = μ = 10⁴ Pa, at the knots) with a Newtonian damping, and no tracks.
Scenario spline_bar(const fs::path& dir) {
  test::ShakenBar b;
  b.material = R"(  density: 1100
  elastic: { model: spline }
  viscous: { model: newtonian, nu: 20 })";
  b.tail = R"(
fit:
  parameters: [elastic.f5]
  objective:
    targets: [ { time: 0.1, select: { plane: { axis: x, at: 0.06 } }, offset: [0, 0, 0] } ]
)";
  test::write_text(dir / "s.yaml", test::shaken_bar_yaml(b));
  return load_scenario((dir / "s.yaml").string());
}

/// Central differences of term.value at p, entry by entry.
Eigen::VectorXd central_differences(const ParameterTerm& term, const Eigen::VectorXd& p, double h) {
  Eigen::VectorXd g(p.size());
  for (int j = 0; j < p.size(); ++j) {
    Eigen::VectorXd a = p, b = p;
    a[j] += h;
    b[j] -= h;
    g[j] = (term.value(a, nullptr) - term.value(b, nullptr)) / (2 * h);
  }
  return g;
}

}  // namespace

// f'(s) of the spline falls by 100 Pa between knots 5 and 6: the term is w · 100²
// (one global value, so the volume shares sum to 1), its gradient ±2w · 100 on the
// two knots, and zero once the curve rises again.
TEST(ParameterTerms, TheSplineSlopeTermPenalisesAFallingStressCurveOnly) {
  const fs::path dir = test::scratch("parameter-terms-spline");
  const Scenario s = spline_bar(dir);
  const std::vector<double> knots = SplineMaterial::neo_hookean_values(1e4, 1e4);
  ASSERT_LT(knots[4], knots[5]);  // the default curve rises
  FitParameterSpec f5 = linear_fit_parameter("elastic.f5", -1e5, 1e5);
  FitParameterSpec f6 = linear_fit_parameter("elastic.f6", -1e5, 1e5);
  f5.initial = knots[4];
  f6.initial = knots[4] - 100;
  FitProblem problem(s, {f5, f6});
  const double w = 1e-9;
  const SplineSlopeTerm term(problem.map(), problem.model(), w);
  EXPECT_EQ(term.pairs(), 3);  // (f4, f5), (f5, f6), (f6, f7)
  Eigen::VectorXd p = problem.map().initial();
  Eigen::VectorXd g = Eigen::VectorXd::Zero(2);
  EXPECT_NEAR(term.value(p, &g), w * 100 * 100, 1e-12 * w * 1e4);
  EXPECT_NEAR(g[0], 2 * w * 100, 1e-12);
  EXPECT_NEAR(g[1], -2 * w * 100, 1e-12);
  EXPECT_LT((g - central_differences(term, p, 1e-3)).norm(), 1e-9 * g.norm());

  p[1] = knots[4] + 100;  // rising again (and still below f7)
  ASSERT_LT(p[1], knots[6]);
  g.setZero();
  EXPECT_EQ(term.value(p, &g), 0.0);
  EXPECT_EQ(g.norm(), 0.0);
}

// A knot fitted by two blocks, a global value and a Legendre multiplier along the
// bar: the penalty's gradient reaches both (central differences).
TEST(ParameterTerms, TheSplineSlopeGradientReachesEveryBlockOfAKnot) {
  const fs::path dir = test::scratch("parameter-terms-spline-blocks");
  const Scenario s = spline_bar(dir);
  const std::vector<double> knots = SplineMaterial::neo_hookean_values(1e4, 1e4);
  FitParameterSpec f6 = linear_fit_parameter("elastic.f6", -1e5, 1e5);
  f6.initial = knots[4] - 100;
  FitParameterSpec along = linear_fit_parameter("elastic.f6", -5, 5);
  along.scope = FitParameterSpec::Scope::Legendre;
  along.legendre_axis = 0;
  along.legendre_degree = 1;
  along.initial = 0.2;
  FitProblem problem(s, {f6, along});
  const SplineSlopeTerm term(problem.map(), problem.model(), 1e-9);
  const Eigen::VectorXd p = problem.map().initial();
  Eigen::VectorXd g = Eigen::VectorXd::Zero(p.size());
  EXPECT_GT(term.value(p, &g), 0);
  ASSERT_GE(p.size(), 2);
  EXPECT_GT(g.tail(p.size() - 1).norm(), 0.0);  // the multiplier's coefficients
  EXPECT_LT((g - central_differences(term, p, 1e-4)).norm(), 1e-6 * g.norm());
}

// γ Σ (p_a − p_b)² over face neighbours of a per-element field: zero on a uniform
// field, its gradient that of central differences elsewhere.
TEST(ParameterTerms, TheSmoothnessTermMeasuresDifferencesAcrossFaces) {
  const fs::path dir = test::scratch("parameter-terms-smoothness");
  const Scenario s = spline_bar(dir);
  FitParameterSpec mu = linear_fit_parameter("elastic.f5", -1e5, 1e5);
  mu.scope = FitParameterSpec::Scope::PerElement;
  FitProblem problem(s, {mu});
  const SmoothnessTerm term(problem.map(), problem.mesh(), 0.5);
  Eigen::VectorXd p = problem.map().initial();
  EXPECT_EQ(term.value(p, nullptr), 0.0);
  for (int j = 0; j < p.size(); ++j) p[j] += 0.01 * (j % 7);
  Eigen::VectorXd g = Eigen::VectorXd::Zero(p.size());
  const double v = term.value(p, &g);
  EXPECT_NEAR(v, 0.5 * term.roughness(p), 1e-15 * v);
  EXPECT_GT(v, 0);
  EXPECT_LT((g - central_differences(term, p, 1e-4)).norm(), 1e-8 * g.norm());
}

// The fit's terms: only those that are switched on and have something to act on.
TEST(ParameterTerms, AFitGetsTheTermsItsOptionsSwitchOn) {
  const fs::path dir = test::scratch("parameter-terms-list");
  const Scenario s = spline_bar(dir);
  FitParameterSpec f5 = linear_fit_parameter("elastic.f5", -1e5, 1e5);
  f5.penalty = 1e-6;
  f5.scale = 1e3;
  FitProblem problem(s, {f5});
  const auto names = [&](double gamma, double slopes) {
    std::vector<std::string> out;
    for (const auto& t : parameter_terms(problem.map(), problem.model(), gamma, slopes))
      out.push_back(t->name());
    return out;
  };
  EXPECT_EQ(names(0, 0), std::vector<std::string>{"priors"});
  EXPECT_EQ(names(1e-3, 1e-9), (std::vector<std::string>{"smoothness", "priors", "spline slopes"}));
  FitProblem viscous_only(s, {positive_fit_parameter("viscous.nu")});
  EXPECT_TRUE(parameter_terms(viscous_only.map(), viscous_only.model(), 0, 1e-9).empty());
}

}  // namespace kelvin
