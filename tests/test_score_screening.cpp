// Screening candidate effects by their score statistic at the nominal fit: the χ²
// tail, the statistic's exactness on a linear model, and on the shaken bar the
// effect put into the data ranked first, no effect found where there is none.
#include <gtest/gtest.h>

#include <Eigen/QR>
#include <cmath>
#include <random>

#include "adjoint/fit_problem.hpp"
#include "adjoint/score_screening.hpp"
#include "adjoint/uncertainty.hpp"
#include "engine/csv.hpp"
#include "fit/fit_loop.hpp"
#include "test_support.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;

TEST(ChiSquare, SurvivalMatchesTabulatedQuantiles) {
  EXPECT_NEAR(chi_square_survival(3.841459, 1), 0.05, 1e-7);
  EXPECT_NEAR(chi_square_survival(5.991465, 2), 0.05, 1e-7);
  EXPECT_NEAR(chi_square_survival(16.26624, 3), 0.001, 1e-8);
  EXPECT_NEAR(chi_square_survival(0.1148318, 3), 0.99, 1e-7);
  EXPECT_NEAR(chi_square_survival(2 * 10.0, 2), std::exp(-10.0), 1e-15);  // k = 2: e^(−x/2)
  EXPECT_EQ(chi_square_survival(0, 4), 1);
}

// For a linear model the Gauss–Newton step is exact: the predicted drop equals the
// drop of the refit with the candidate, and the statistic is the F-test's numerator.
TEST(ScoreScreening, IsExactOnALinearModel) {
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0, 0.1);
  const int N = 400;
  Eigen::MatrixXd J(N, 4);
  Eigen::VectorXd y(N);
  for (int i = 0; i < N; ++i) {
    const double t = i / double(N);
    J.row(i) << 1, t, std::sin(7 * t), t * t * t;
    y[i] = 2 + 3 * t + 0.4 * std::sin(7 * t) + noise(rng);  // column 3 has no effect
  }
  // The nominal fit: columns 0 and 1; r = model − data at the fitted θ.
  const Eigen::MatrixXd A = J.leftCols(2);
  const Eigen::VectorXd theta = A.colPivHouseholderQr().solve(y);
  const Eigen::VectorXd r = A * theta - y;
  const auto s = score_candidates(r, J, {0, 1}, {{"sine", {2}}, {"cubic", {3}}, {"both", {2, 3}}});
  ASSERT_EQ(s.size(), 3u);
  for (int k = 0; k < 3; ++k) {
    std::vector<int> cols = {0, 1};
    for (int e : s[k].entries) cols.push_back(e);
    Eigen::MatrixXd B(N, static_cast<long>(cols.size()));
    for (size_t c = 0; c < cols.size(); ++c) B.col(static_cast<long>(c)) = J.col(cols[c]);
    const Eigen::VectorXd refit = B * B.colPivHouseholderQr().solve(y) - y;
    EXPECT_NEAR(s[k].predicted_drop, r.squaredNorm() - refit.squaredNorm(), 1e-9 * r.squaredNorm())
        << s[k].name;
  }
  EXPECT_LT(s[0].p_value, 1e-10);  // the sine is in the data
  EXPECT_GT(s[0].predicted_drop, s[1].predicted_drop);
  EXPECT_EQ(s[2].dof, 2);
  // The cubic alone picks up part of the sine; once the sine is accepted it is not
  // significant: screening again after accepting an effect.
  const Eigen::MatrixXd A3 = J.leftCols(3);
  const Eigen::VectorXd r3 = A3 * A3.colPivHouseholderQr().solve(y) - y;
  const auto again = score_candidates(r3, J, {0, 1, 2}, {{"cubic", {3}}});
  EXPECT_GT(again[0].p_value, 1e-3) << again[0].statistic;
  // A candidate that only repeats a fitted direction is reported, not scored.
  const auto twin = score_candidates(r, J, {0, 1}, {{"slope again", {1}}});
  EXPECT_FALSE(twin[0].error.empty());
}

TEST(ChiSquare, QuantileInvertsTheSurvival) {
  EXPECT_NEAR(chi_square_quantile(0.05, 1), 3.841459, 1e-5);
  EXPECT_NEAR(chi_square_quantile(0.001, 3), 16.26624, 1e-4);
  for (int k : {1, 2, 5, 40})
    for (double p : {0.5, 1e-2, 1e-6})
      EXPECT_NEAR(chi_square_survival(chi_square_quantile(p, k), k), p, 1e-9 * std::max(p, 1e-3));
}

// A nested modulus at its bound: the data asking for a negative value is no
// evidence for it (the constrained refit stays at 0), and of two bounded columns
// only the one with an admissible step is used.
TEST(ScoreScreening, BoundedEntriesTakeNoStepBelowTheirBound) {
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0, 0.1);
  const int N = 300;
  Eigen::MatrixXd J(N, 3);
  Eigen::VectorXd y(N);
  for (int i = 0; i < N; ++i) {
    const double t = i / double(N);
    J.row(i) << 1, std::sin(5 * t), std::cos(11 * t);
    y[i] = 1 - 0.5 * std::sin(5 * t) + 0.3 * std::cos(11 * t) + noise(rng);
  }
  const Eigen::VectorXd r = J.col(0) * J.col(0).dot(y) / N - y;  // nominal: the mean
  ScreeningOptions o;
  o.nonnegative = {1, 2};
  o.noise_variance = 0.01;  // the sine left in r would inflate ‖r‖² / (N − 1) 13×
  const auto s = score_candidates(r, J, {0}, {{"sine", {1}}, {"cosine", {2}}, {"both", {1, 2}}}, o);
  EXPECT_EQ(s[0].predicted_drop, 0);  // the data want −0.5
  EXPECT_TRUE(s[0].active.empty());
  EXPECT_GT(s[1].statistic, 100);
  ASSERT_EQ(s[1].step.size(), 1);
  // On a linear model the step is the refit's coefficient (the constant refitted too).
  Eigen::MatrixXd B(N, 2);
  B << J.col(0), J.col(2);
  EXPECT_NEAR(s[1].step[0], B.colPivHouseholderQr().solve(y)[1], 1e-10);
  ASSERT_EQ(s[2].active, std::vector<int>{2});
  EXPECT_NEAR(s[2].predicted_drop, s[1].predicted_drop, 1e-12);
  // Unbounded, the sine's step is its (negative) coefficient.
  const auto free = score_candidates(r, J, {0}, {{"sine", {1}}});
  ASSERT_EQ(free[0].step.size(), 1);
  B.col(1) = J.col(1);
  EXPECT_NEAR(free[0].step[0], B.colPivHouseholderQr().solve(y)[1], 1e-10);
  EXPECT_LT(free[0].step[0], 0);
}

// A fitted entry whose column is a thousand-millionth of the others' (V07's λ fitted
// to 0.0036 Pa beside μ at 1.4e5 Pa): its unit column is a direction like any other,
// and the step divided its coefficient by the vanishing norm. Held, it stays put,
// the others' step is the least-squares one without it, and the score is unchanged.
TEST(ScoreScreening, AHeldFittedEntryTakesNoStep) {
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0, 0.1);
  const int N = 300;
  Eigen::MatrixXd J(N, 3);
  Eigen::VectorXd y(N);
  for (int i = 0; i < N; ++i) {
    const double t = i / double(N);
    J.row(i) << 1, 1e-9 * t * t, std::sin(7 * t);
    y[i] = 2 + 0.4 * std::sin(7 * t) + noise(rng);
  }
  const Eigen::VectorXd theta = J.leftCols(2).colPivHouseholderQr().solve(y);
  const Eigen::VectorXd r = J.leftCols(2) * theta - y;
  const auto loose = score_candidates(r, J, {0, 1}, {{"sine", {2}}});
  ASSERT_EQ(loose[0].fitted_step.size(), 2);
  EXPECT_GT(std::abs(loose[0].fitted_step[1]), 1e6);
  ScreeningOptions o;
  o.held = {1};
  const auto held = score_candidates(r, J, {0, 1}, {{"sine", {2}}}, o);
  ASSERT_EQ(held[0].fitted_step.size(), 2);
  EXPECT_EQ(held[0].fitted_step[1], 0);
  ASSERT_EQ(held[0].step.size(), 1);
  const Eigen::VectorXd rest = -(r + J.col(2) * held[0].step[0]);
  EXPECT_NEAR(held[0].fitted_step[0], J.col(0).dot(rest) / J.col(0).squaredNorm(), 1e-12);
  EXPECT_EQ(held[0].statistic, loose[0].statistic);
}

TEST(ScoreScreening, ConfoundingIsTheCanonicalCorrelation) {
  const int N = 500;
  Eigen::MatrixXd J(N, 4);
  for (int i = 0; i < N; ++i) {
    const double t = i / double(N);
    J.row(i) << 1, t, t + 0.01 * std::sin(40 * t), std::sin(9 * t);
  }
  // Columns 1 and 2 are nearly the same effect; 3 is another one.
  EXPECT_GT(confounding(J, {0}, {1}, {2}), 0.99);
  EXPECT_LT(confounding(J, {0}, {1}, {3}), 0.9);
  EXPECT_NEAR(confounding(J, {0}, {1, 3}, {3}), 1, 1e-12);  // a shared column
}

// ---- the shaken bar of the gradient tests ---------------------------------------

const std::string& kMarkers = test::kShakenBarMarkers;

std::string bar(const std::string& material, const std::string& tail) {
  test::ShakenBar b;
  b.material = material;
  b.end = 0.15;
  b.rtol = 1e-8;
  b.atol = 1e-12;
  b.tail = tail;
  return test::shaken_bar_yaml(b);
}

// The model a user would fit, with the candidates switched off (all at 0).
const std::string kExtended = R"(  density: 1100
  elastic:
    - { model: neo-hookean, lambda: 2.0e5, mu: 0.8e5 }
    - { model: stiffening, c2: 0 }
    - { model: fibre, k: 0, theta: 0.7853981633974483, phi: 1.5707963267948966 }
  viscous:
    - { model: newtonian, nu: 30 }
    - { model: drag, c: 0 })";

/// Nominal fit of μ and ν, then the scores of stiffening, fibre and drag there.
std::vector<CandidateScore> screen(const fs::path& dir, const std::string& tracks) {
  test::write_text(dir / "fit.yaml", bar(kExtended, kMarkers + "\n  observed: " + tracks + "\n"));
  const Scenario s = load_scenario((dir / "fit.yaml").string());
  const std::vector<FitParameterSpec> nominal = {positive_fit_parameter("elastic.mu"),
                                                 positive_fit_parameter("viscous.nu")};
  FitProblem fit(s, nominal);
  FitOptions o;
  o.max_evaluations = 40;
  const FitOutcome out = run_fit(fit, fit.map().initial(), o);
  EXPECT_GT(out.evaluations, 0);
  std::vector<FitParameterSpec> all = nominal;
  all.push_back(linear_fit_parameter("elastic.c2", 0, 1e8));
  all.push_back(linear_fit_parameter("elastic.k", 0, 1e8));
  all.push_back(linear_fit_parameter("viscous.c", 0, 1e5));
  FitProblem extended(s, all);
  Eigen::VectorXd p = extended.map().initial();
  p.head(2) = out.p;
  const GaussNewtonSystem g = gauss_newton_system(extended, p);
  EXPECT_TRUE(g.ok) << g.error;
  return score_candidates(g.residual, g.jacobian, {0, 1},
                          {{"stiffening", {2}}, {"fibre", {3}}, {"drag", {4}}});
}

const std::string kNominalTruth = R"(  density: 1100
  elastic: { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
  viscous: { model: newtonian, nu: 20 })";

TEST(ScoreScreening, RanksTheEffectInTheDataFirst) {
  const fs::path dir = test::scratch("screen-stiffening");
  const std::string truth = R"(  density: 1100
  elastic:
    - { model: neo-hookean, lambda: 2.0e5, mu: 1.0e5 }
    - { model: stiffening, c2: 3.0e5 }
  viscous: { model: newtonian, nu: 20 })";
  const std::string tracks = test::noisy_tracks(
      test::simulate_tracks(dir, "truth", bar(truth, kMarkers)), dir / "noisy.csv", 2e-6, 5);
  const auto s = screen(dir, tracks);
  ASSERT_EQ(s.size(), 3u);
  for (const auto& c : s) RecordProperty(c.name, fmt::format("{:.3g}", c.statistic));
  EXPECT_GT(s[0].predicted_drop, s[1].predicted_drop);
  EXPECT_GT(s[0].predicted_drop, s[2].predicted_drop);
  EXPECT_LT(s[0].p_value, 1e-6) << s[0].statistic;
  EXPECT_LT(s[0].predicted_rms, 0.5 * s[0].rms_before);
}

// The nominal model and noise: no candidate is significant at 10⁻³ per candidate.
TEST(ScoreScreening, FindsNoEffectWhereThereIsNone) {
  const fs::path dir = test::scratch("screen-none");
  const std::string tracks =
      test::noisy_tracks(test::simulate_tracks(dir, "truth", bar(kNominalTruth, kMarkers)),
                         dir / "noisy.csv", 2e-5, 7);
  const auto s = screen(dir, tracks);
  ASSERT_EQ(s.size(), 3u);
  for (const auto& c : s) {
    EXPECT_TRUE(c.error.empty()) << c.error;
    EXPECT_GT(c.p_value, 1e-3) << c.name << ": LM " << c.statistic;
  }
}

}  // namespace
}  // namespace kelvin
