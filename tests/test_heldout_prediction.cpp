// The held-out drop a candidate's screening step predicts: exact on a linear model,
// and it puts an effect of the specimen before an artefact of the training capture
// that the training score prefers.
#include <gtest/gtest.h>

#include <Eigen/QR>
#include <cmath>
#include <limits>
#include <random>

#include "adjoint/score_screening.hpp"
#include "diagnose/heldout_prediction.hpp"

namespace kelvin {
namespace {

// Columns: offset, slope (fitted), a sine (the specimen's effect, in both motions),
// a fast wobble (an artefact of the training capture: absent in the held-out).
Eigen::MatrixXd design(int n, double t0, double t1, bool training) {
  Eigen::MatrixXd J(n, 4);
  for (int i = 0; i < n; ++i) {
    const double t = t0 + (t1 - t0) * i / (n - 1.0);
    J.row(i) << 1, t, std::sin(7 * t), training ? std::cos(40 * t) : 0.0;
  }
  return J;
}

TEST(HeldOutPrediction, IsTheRefitsHeldOutDropOnALinearModelAndPrefersTheSpecimensEffect) {
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0, 0.05);
  const int N = 300;
  const Eigen::MatrixXd J = design(N, 0, 1, true), Jh = design(N, 1, 2.5, false);
  const Eigen::Vector4d truth(2, 3, 0.15, 0.8);
  Eigen::VectorXd y = J * truth, yh = Jh * truth;
  for (int i = 0; i < N; ++i) y[i] += noise(rng), yh[i] += noise(rng);
  const Eigen::VectorXd theta = J.leftCols(2).colPivHouseholderQr().solve(y);
  const Eigen::VectorXd r = J.leftCols(2) * theta - y, h = Jh.leftCols(2) * theta - yh;
  const std::vector<int> fitted = {0, 1};
  const auto s = score_candidates(r, J, fitted, {{"sine", {2}}, {"artefact", {3}}});
  ASSERT_EQ(s.size(), 2u);
  std::vector<double> drop;
  for (const auto& c : s) {
    // The refit: θ and the candidate free on the training data, applied to held-out.
    const std::vector<int> cols = {0, 1, c.entries[0]};
    Eigen::MatrixXd B(N, 3), Bh(N, 3);
    for (int k = 0; k < 3; ++k) B.col(k) = J.col(cols[k]), Bh.col(k) = Jh.col(cols[k]);
    const Eigen::VectorXd beta = B.colPivHouseholderQr().solve(y);
    const double refit_drop = h.squaredNorm() - (Bh * beta - yh).squaredNorm();
    drop.push_back(predicted_heldout_drop(h, Jh, c, fitted));
    EXPECT_NEAR(drop.back(), refit_drop, 1e-9 * h.squaredNorm()) << c.name;
  }
  // The training score prefers the artefact; held out, it makes things worse.
  EXPECT_GT(s[1].statistic, s[0].statistic);
  EXPECT_GT(drop[0], 0);
  EXPECT_LT(drop[1], drop[0]);
  EXPECT_EQ(order_by_heldout({1, 0}, drop), (std::vector<int>{0, 1}));
}

TEST(HeldOutPrediction, UnpredictedCandidatesKeepTheirOrderAfterThePredicted) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<double> drop = {nan, 2.0, nan, 5.0, -1.0};
  EXPECT_EQ(order_by_heldout({0, 1, 2, 3, 4}, drop), (std::vector<int>{3, 1, 4, 0, 2}));
  EXPECT_EQ(order_by_heldout({2, 0}, drop), (std::vector<int>{2, 0}));
}

TEST(HeldOutPrediction, ACandidateTheDataCannotSeePredictsNothing) {
  CandidateScore s;
  s.error = "moves the markers only as the fitted parameters do";
  const Eigen::VectorXd h = Eigen::VectorXd::Ones(5);
  EXPECT_EQ(predicted_heldout_drop(h, Eigen::MatrixXd::Ones(5, 2), s, {0}), 0);
}

}  // namespace
}  // namespace kelvin
