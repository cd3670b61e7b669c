#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <vector>

#include "base/error.hpp"
#include "engine/rigid_motion.hpp"

namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;
using Eigen::Vector4d;

kelvin::SinusoidMotion make_sinusoid() {
  std::vector<kelvin::Sinusoid> tr = {{0.01, 1.3, 0.2, Vector3d(1, 0, 0)},
                                      {0.004, 2.1, -0.7, Vector3d(0, 3, 4)}};  // normalised inside
  std::vector<kelvin::Sinusoid> rot = {{0.3, 0.9, 0.4}, {0.1, 1.7, 1.1}};
  return kelvin::SinusoidMotion(tr, rot, Vector3d(1, 2, 3), Vector3d(0.05, -0.02, 0.1));
}

/// Fourth-order central differences of x(t) = pose(t).position(X).
template <class M>
Vector3d fd_velocity(const M& m, double t, const Vector3d& X, double h) {
  auto p = [&](double s) { return m.at(s).position(X); };
  return (8 * (p(t + h) - p(t - h)) - (p(t + 2 * h) - p(t - 2 * h))) / (12 * h);
}
template <class M>
Vector3d fd_acceleration(const M& m, double t, const Vector3d& X, double h) {
  auto p = [&](double s) { return m.at(s).position(X); };
  return (-p(t + 2 * h) + 16 * p(t + h) - 30 * p(t) + 16 * p(t - h) - p(t - 2 * h)) / (12 * h * h);
}

double rel_err(const Vector3d& a, const Vector3d& exact) {
  return (a - exact).norm() / std::max(exact.norm(), 1e-12);
}

void expect_rotation(const Matrix3d& R) {
  EXPECT_LT((R.transpose() * R - Matrix3d::Identity()).norm(), 1e-13);
  EXPECT_NEAR(R.determinant(), 1.0, 1e-13);
}

TEST(RigidMotion, FixedMotionIsIdentityForever) {
  kelvin::FixedMotion m;
  const auto p = m.at(3.0);
  EXPECT_EQ(p.R, Matrix3d::Identity());
  EXPECT_EQ(p.d, Vector3d::Zero());
  EXPECT_EQ(m.end_time(), std::numeric_limits<double>::infinity());
}

TEST(SinusoidMotion, DerivativesMatchFiniteDifferencesOfPosition) {
  const auto m = make_sinusoid();
  EXPECT_EQ(m.end_time(), std::numeric_limits<double>::infinity());
  const std::vector<Vector3d> Xs = {Vector3d(0.1, 0.2, -0.05), Vector3d(-0.3, 0.0, 0.4),
                                    Vector3d(0, 0, 0)};
  for (double t : {0.0, 0.137, 0.5, 1.234, 3.9}) {
    const auto pose = m.at(t);
    expect_rotation(pose.R);
    for (const auto& X : Xs) {
      EXPECT_LT(rel_err(fd_velocity(m, t, X, 1e-3), pose.velocity(X)), 1e-6) << "t=" << t;
      EXPECT_LT(rel_err(fd_acceleration(m, t, X, 5e-4), pose.acceleration(X)), 1e-6) << "t=" << t;
    }
  }
}

TEST(SinusoidMotion, RotationAboutCenterKeepsCenterFixed) {
  const Vector3d axis(0, 0, 1), c(0.2, -0.1, 0.3);
  kelvin::SinusoidMotion m({}, {{0.5, 1.0, 0.3}}, axis, c);
  for (double t : {0.0, 0.1, 0.77}) {
    const auto pose = m.at(t);
    EXPECT_LT((pose.position(c) - c).norm(), 1e-15);
    EXPECT_LT(pose.velocity(c).norm(), 1e-14);
    EXPECT_LT(pose.acceleration(c).norm(), 1e-13);
    // Any other point turns by θ(t) about the axis through c.
    const double th = 0.5 * std::sin(2 * std::numbers::pi * t + 0.3);
    const Vector3d X(1.0, 0.5, -0.2);
    const Vector3d expect = Eigen::AngleAxisd(th, axis) * (X - c) + c;
    EXPECT_LT((pose.position(X) - expect).norm(), 1e-14);
  }
}

TEST(SinusoidMotion, PureTranslation) {
  kelvin::SinusoidMotion m({{0.02, 0.5, 0.0, Vector3d(0, 2, 0)}}, {}, Vector3d::UnitZ(),
                           Vector3d::Zero());
  const auto p = m.at(0.5);  // sin(π/2) = 1
  EXPECT_NEAR(p.d.y(), 0.02, 1e-15);
  EXPECT_NEAR(p.d.x(), 0.0, 1e-15);
  EXPECT_EQ(p.R, Matrix3d::Identity());
  EXPECT_NEAR(p.dddot.y(), -0.02 * std::pow(std::numbers::pi, 2), 1e-14);
}

/// Rows of a sampled motion, quaternions deliberately not normalised.
struct Samples {
  std::vector<double> t;
  std::vector<Vector3d> d;
  std::vector<Vector4d> q;
};
Samples irregular_samples() {
  Samples s;
  s.t = {0.0, 0.1, 0.25, 0.3, 0.55, 0.8};
  for (size_t i = 0; i < s.t.size(); ++i) {
    const double t = s.t[i];
    s.d.emplace_back(0.01 * t, -0.02 * t * t, 0.005 * std::sin(3 * t));
    const Eigen::Quaterniond q(Eigen::AngleAxisd(1.2 * t, Vector3d(1, 1, 0).normalized()));
    s.q.push_back(Vector4d(q.w(), q.x(), q.y(), q.z()) * (1.0 + 0.5 * i));
  }
  return s;
}

TEST(SampledMotion, InterpolatesSamplesExactly) {
  const auto s = irregular_samples();
  kelvin::SampledMotion m(s.t, s.d, s.q);
  EXPECT_EQ(m.start_time(), 0.0);
  EXPECT_EQ(m.end_time(), 0.8);
  const Vector3d X(0.1, -0.2, 0.3);
  for (size_t i = 0; i < s.t.size(); ++i) {
    const auto pose = m.at(s.t[i]);
    const Eigen::Quaterniond q(s.q[i][0], s.q[i][1], s.q[i][2], s.q[i][3]);
    EXPECT_LT((pose.R - q.normalized().toRotationMatrix()).norm(), 1e-14) << i;
    EXPECT_LT((pose.d - s.d[i]).norm(), 1e-15) << i;
    EXPECT_LT((pose.position(X) - (q.normalized() * X + s.d[i])).norm(), 1e-14) << i;
  }
}

TEST(SampledMotion, DerivativesMatchFiniteDifferencesAndRIsOrthonormal) {
  const auto s = irregular_samples();
  kelvin::SampledMotion m(s.t, s.d, s.q);
  const Vector3d X(0.1, -0.2, 0.3);
  // Interior points of intervals: the spline is C2 but its third derivative jumps at
  // knots, so the finite-difference stencils must not straddle one.
  for (double t : {0.05, 0.17, 0.22, 0.275, 0.4, 0.7}) {
    const auto pose = m.at(t);
    expect_rotation(pose.R);  // q is far from unit length here
    EXPECT_LT(rel_err(fd_velocity(m, t, X, 1e-4), pose.velocity(X)), 1e-6) << "t=" << t;
    EXPECT_LT(rel_err(fd_acceleration(m, t, X, 1e-3), pose.acceleration(X)), 1e-6) << "t=" << t;
    // Rdot and Rddot themselves, not only their action on one point.
    const double h = 1e-4;
    const Matrix3d R1 = (m.at(t + h).R - m.at(t - h).R) / (2 * h);
    const Matrix3d R2 = (m.at(t + h).R - 2 * pose.R + m.at(t - h).R) / (h * h);
    EXPECT_LT((R1 - pose.Rdot).norm(), 1e-6 * pose.Rdot.norm());
    EXPECT_LT((R2 - pose.Rddot).norm(), 1e-4 * pose.Rddot.norm());
  }
}

TEST(SampledMotion, HoldsEndPosesOutsideTheSamples) {
  const auto s = irregular_samples();
  kelvin::SampledMotion m(s.t, s.d, s.q);
  const auto before = m.at(-1.0), first = m.at(0.0);
  EXPECT_LT((before.R - first.R).norm(), 1e-15);
  EXPECT_LT((before.d - first.d).norm(), 1e-15);
  EXPECT_EQ(before.Rdot, Matrix3d::Zero());
  EXPECT_EQ(before.ddot, Vector3d::Zero());
  const auto after = m.at(5.0), last = m.at(0.8);
  EXPECT_LT((after.position(Vector3d(1, 2, 3)) - last.position(Vector3d(1, 2, 3))).norm(), 1e-15);
  EXPECT_EQ(after.Rddot, Matrix3d::Zero());
  EXPECT_EQ(after.dddot, Vector3d::Zero());
}

TEST(SampledMotion, RefusesBadSamples) {
  auto s = irregular_samples();
  auto t = s.t;
  t[3] = t[2];
  EXPECT_THROW(kelvin::SampledMotion(t, s.d, s.q), kelvin::Error);
  EXPECT_THROW(kelvin::SampledMotion({0.0}, {Vector3d::Zero()}, {Vector4d(1, 0, 0, 0)}),
               kelvin::Error);
  auto q = s.q;
  q[1].setZero();
  EXPECT_THROW(kelvin::SampledMotion(s.t, s.d, q), kelvin::Error);
  s.d.pop_back();
  EXPECT_THROW(kelvin::SampledMotion(s.t, s.d, s.q), kelvin::Error);
}

TEST(SampledMotion, ReproducesSmoothMotionSampledAt200Hz) {
  // A rigid motion about the origin (the clamp CSV convention) sampled like a capture.
  const auto truth = make_sinusoid();
  Samples s;
  const double dt = 1.0 / 200;
  for (int i = 0; i <= 400; ++i) {
    const double t = i * dt;
    const auto p = truth.at(t);
    const Eigen::Quaterniond q(p.R);
    Vector4d qv(q.w(), q.x(), q.y(), q.z());
    if (!s.q.empty() && qv.dot(s.q.back()) < 0) qv = -qv;
    s.t.push_back(t);
    s.d.push_back(p.d);
    s.q.push_back(qv);
  }
  kelvin::SampledMotion m(s.t, s.d, s.q);
  const Vector3d X(0.1, 0.2, -0.05);
  double pos_err = 0, vel_err = 0, acc_err = 0, disp = 0, vel = 0, acc = 0;
  // Stay away from the ends, where the natural end condition (S'' = 0) costs O(h²)
  // accuracy; its influence decays geometrically into the interior.
  for (double t = 0.3; t < 1.7; t += 0.00731) {
    const auto a = truth.at(t), b = m.at(t);
    pos_err = std::max(pos_err, (a.position(X) - b.position(X)).norm());
    vel_err = std::max(vel_err, (a.velocity(X) - b.velocity(X)).norm());
    acc_err = std::max(acc_err, (a.acceleration(X) - b.acceleration(X)).norm());
    disp = std::max(disp, (a.position(X) - X).norm());
    vel = std::max(vel, a.velocity(X).norm());
    acc = std::max(acc, a.acceleration(X).norm());
    expect_rotation(b.R);
  }
  EXPECT_LT(pos_err, 1e-6 * disp);
  EXPECT_LT(vel_err, 1e-4 * vel);  // O(h³)
  EXPECT_LT(acc_err, 1e-3 * acc);  // O(h²)
  std::printf("sampled 200 Hz: rel err pos %.3g vel %.3g acc %.3g\n", pos_err / disp, vel_err / vel,
              acc_err / acc);
}

}  // namespace
