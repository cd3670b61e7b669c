#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "engine/cubic_spline.hpp"

namespace kelvin {
namespace {

/// The d-th derivative of the spline with knot values y and slopes m at time t.
Eigen::VectorXd evaluate(const std::vector<double>& t, const Eigen::MatrixXd& y,
                         const Eigen::MatrixXd& m, double time, int d) {
  size_t k = 0;
  while (k + 2 < t.size() && time > t[k + 1]) ++k;
  const double h = t[k + 1] - t[k];
  return hermite(y.col(k), m.col(k), y.col(k + 1), m.col(k + 1), (time - t[k]) / h, h, d);
}

// p(t) = 1 − 2t + 3t² − 5t³ and q(t) = 4t³ + t, with derivatives.
Eigen::Vector2d cubic(double t, int d) {
  switch (d) {
    case 0:
      return {1 - 2 * t + 3 * t * t - 5 * t * t * t, 4 * t * t * t + t};
    case 1:
      return {-2 + 6 * t - 15 * t * t, 12 * t * t + 1};
    default:
      return {6 - 30 * t, 24 * t};
  }
}

Eigen::MatrixXd sample(const std::vector<double>& t) {
  Eigen::MatrixXd y(2, t.size());
  for (size_t k = 0; k < t.size(); ++k) y.col(k) = cubic(t[k], 0);
  return y;
}

TEST(CubicSpline, NotAKnotReproducesACubicExactlyOnUnevenKnots) {
  const std::vector<double> t = {0, 0.1, 0.25, 0.3, 0.55, 0.7, 1.0};
  const Eigen::MatrixXd y = sample(t);
  const Eigen::MatrixXd m = cubic_spline_slopes(t, y, SplineEnds::kNotAKnot);
  for (size_t k = 0; k < t.size(); ++k)
    EXPECT_LT((m.col(k) - cubic(t[k], 1)).norm(), 1e-12) << "knot " << k;
  for (double time : {0.0, 0.03, 0.17, 0.29, 0.5, 0.61, 0.99, 1.0})
    for (int d = 0; d < 3; ++d)
      EXPECT_LT((evaluate(t, y, m, time, d) - cubic(time, d)).norm(), 1e-10)
          << "t = " << time << ", derivative " << d;
}

TEST(CubicSpline, NotAKnotOnFourKnotsIsTheInterpolatingCubic) {
  const std::vector<double> t = {0.2, 0.5, 0.6, 1.1};
  const Eigen::MatrixXd m = cubic_spline_slopes(t, sample(t), SplineEnds::kNotAKnot);
  for (size_t k = 0; k < t.size(); ++k) EXPECT_LT((m.col(k) - cubic(t[k], 1)).norm(), 1e-12);
}

TEST(CubicSpline, ThreeKnotsGiveTheParabolaAndTwoTheSecant) {
  const std::vector<double> t3 = {0, 0.2, 0.5};
  Eigen::MatrixXd y3(1, 3);
  for (int k = 0; k < 3; ++k) y3(0, k) = 2 - t3[k] + 7 * t3[k] * t3[k];
  const Eigen::MatrixXd m3 = cubic_spline_slopes(t3, y3, SplineEnds::kNotAKnot);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(m3(0, k), -1 + 14 * t3[k], 1e-12);

  const std::vector<double> t2 = {1, 1.5};
  Eigen::MatrixXd y2(1, 2);
  y2 << 3, 4;
  for (SplineEnds ends : {SplineEnds::kNotAKnot, SplineEnds::kNatural}) {
    const Eigen::MatrixXd m2 = cubic_spline_slopes(t2, y2, ends);
    EXPECT_NEAR(m2(0, 0), 2, 1e-14);
    EXPECT_NEAR(m2(0, 1), 2, 1e-14);
  }
}

TEST(CubicSpline, NaturalEndsAreStraightAndTheInteriorIsTwiceDifferentiable) {
  const std::vector<double> t = {0, 0.3, 0.4, 0.8, 1.3, 1.4};
  Eigen::MatrixXd y(1, t.size());
  for (size_t k = 0; k < t.size(); ++k) y(0, k) = std::cos(3 * t[k]) + t[k];
  const Eigen::MatrixXd m = cubic_spline_slopes(t, y, SplineEnds::kNatural);
  auto second = [&](size_t k, double s) {
    const double h = t[k + 1] - t[k];
    return hermite(y.col(k), m.col(k), y.col(k + 1), m.col(k + 1), s, h, 2)(0);
  };
  EXPECT_NEAR(second(0, 0), 0, 1e-12);
  EXPECT_NEAR(second(t.size() - 2, 1), 0, 1e-12);
  for (size_t k = 1; k + 1 < t.size(); ++k)
    EXPECT_NEAR(second(k - 1, 1), second(k, 0), 1e-10) << "knot " << k;
}

/// Largest error of the not-a-knot spline through sin(2π f t) sampled every h on
/// [0, 0.4], over 20 points per interval inside [0.1, 0.3] (the end intervals
/// converge faster from a larger start: 7× the interior's error at 180 frames/s).
double sine_error(double h) {
  const double f = 35, w = 2 * std::numbers::pi * f;
  std::vector<double> t;
  for (int k = 0; k * h <= 0.4 + 1e-12; ++k) t.push_back(k * h);
  Eigen::MatrixXd y(1, t.size());
  for (size_t k = 0; k < t.size(); ++k) y(0, k) = std::sin(w * t[k]);
  const Eigen::MatrixXd m = cubic_spline_slopes(t, y, SplineEnds::kNotAKnot);
  double err = 0;
  for (size_t k = 0; k + 1 < t.size(); ++k)
    for (int j = 0; j <= 20; ++j) {
      const double time = t[k] + (t[k + 1] - t[k]) * j / 20.0;
      if (time < 0.1 || time > 0.3) continue;
      err = std::max(err, std::abs(evaluate(t, y, m, time, 0)(0) - std::sin(w * time)));
    }
  return err;
}

TEST(CubicSpline, ErrorFallsAsTheFourthPowerOfTheFrameInterval) {
  // A 35 Hz oscillation (the bench bar's ringing) at 720, 1440 and 2880 frames/s.
  const double w = 2 * std::numbers::pi * 35;
  const std::vector<double> h = {1 / 720.0, 1 / 1440.0, 1 / 2880.0};
  std::vector<double> e;
  for (double hh : h) e.push_back(sine_error(hh));
  EXPECT_NEAR(std::log2(e[0] / e[1]), 4, 0.05) << e[0] << " " << e[1];
  EXPECT_NEAR(std::log2(e[1] / e[2]), 4, 0.02) << e[1] << " " << e[2];
  // The spline's slopes are exact to O(h⁴), so its error is that of the cubic
  // Hermite with exact slopes: h⁴ max|f''''| / 384 at mid-interval.
  for (size_t k = 1; k < h.size(); ++k)
    EXPECT_NEAR(e[k] / (std::pow(h[k] * w, 4) / 384), 1, 0.02) << "h = " << h[k];
}

}  // namespace
}  // namespace kelvin
