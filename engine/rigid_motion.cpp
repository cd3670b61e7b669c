#include "engine/rigid_motion.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "base/error.hpp"
#include "engine/cubic_spline.hpp"

namespace kelvin {

double RigidMotion::end_time() const {
  return std::numeric_limits<double>::infinity();
}

SinusoidMotion::SinusoidMotion(std::vector<Sinusoid> translation, std::vector<Sinusoid> rotation,
                               Eigen::Vector3d axis, Eigen::Vector3d center)
    : translation_(std::move(translation)), rotation_(std::move(rotation)), center_(center) {
  axis_ = axis.norm() > 0 ? axis.normalized() : Eigen::Vector3d::UnitZ();
  for (auto& s : translation_)
    if (s.direction.norm() > 0) s.direction.normalize();
}

RigidPose SinusoidMotion::at(double t) const {
  RigidPose p;
  for (const auto& s : translation_) {
    const double w = 2 * std::numbers::pi * s.frequency, a = w * t + s.phase;
    p.d += s.amplitude * std::sin(a) * s.direction;
    p.ddot += s.amplitude * w * std::cos(a) * s.direction;
    p.dddot -= s.amplitude * w * w * std::sin(a) * s.direction;
  }
  if (rotation_.empty()) return p;
  double th = 0, th1 = 0, th2 = 0;  // angle and its time derivatives
  for (const auto& s : rotation_) {
    const double w = 2 * std::numbers::pi * s.frequency, a = w * t + s.phase;
    th += s.amplitude * std::sin(a);
    th1 += s.amplitude * w * std::cos(a);
    th2 -= s.amplitude * w * w * std::sin(a);
  }
  // Rodrigues: R = I + sin θ K + (1 − cos θ) K², differentiated in θ exactly.
  Eigen::Matrix3d K;
  K << 0, -axis_.z(), axis_.y(), axis_.z(), 0, -axis_.x(), -axis_.y(), axis_.x(), 0;
  const Eigen::Matrix3d K2 = K * K;
  const double s = std::sin(th), c = std::cos(th);
  const Eigen::Matrix3d dR = c * K + s * K2, d2R = -s * K + c * K2;
  p.R = Eigen::Matrix3d::Identity() + s * K + (1 - c) * K2;
  p.Rdot = dR * th1;
  p.Rddot = d2R * th1 * th1 + dR * th2;
  // About `center`: x = R (X − c) + c + d  ⇒  offset c − R c.
  p.d += center_ - p.R * center_;
  p.ddot -= p.Rdot * center_;
  p.dddot -= p.Rddot * center_;
  return p;
}

namespace {

/// Bilinear form with M(q) = B(q, q) the unnormalised rotation matrix of q = (w, x, y, z).
Eigen::Matrix3d rotation_bilinear(const Eigen::Vector4d& a, const Eigen::Vector4d& b) {
  auto sym = [&](int i, int j) { return 0.5 * (a[i] * b[j] + a[j] * b[i]); };
  const int w = 0, x = 1, y = 2, z = 3;
  Eigen::Matrix3d M;
  M << sym(w, w) + sym(x, x) - sym(y, y) - sym(z, z), 2 * (sym(x, y) - sym(w, z)),
      2 * (sym(x, z) + sym(w, y)), 2 * (sym(x, y) + sym(w, z)),
      sym(w, w) - sym(x, x) + sym(y, y) - sym(z, z), 2 * (sym(y, z) - sym(w, x)),
      2 * (sym(x, z) - sym(w, y)), 2 * (sym(y, z) + sym(w, x)),
      sym(w, w) - sym(x, x) - sym(y, y) + sym(z, z);
  return M;
}

}  // namespace

SampledMotion::SampledMotion(std::vector<double> t, std::vector<Eigen::Vector3d> d,
                             std::vector<Eigen::Vector4d> q_wxyz)
    : t_(std::move(t)) {
  const int n = static_cast<int>(t_.size());
  if (n < 2 || static_cast<int>(d.size()) != n || static_cast<int>(q_wxyz.size()) != n)
    throw Error(
        "a sampled clamp motion needs at least 2 samples of time, translation and rotation");
  for (int i = 1; i < n; ++i)
    if (!(t_[i] > t_[i - 1]))
      throw Error(
          fmt::format("sampled clamp motion: time {} (sample {}) does not increase", t_[i], i));
  for (int i = 0; i < n; ++i)
    if (!(q_wxyz[i].norm() > 1e-12))
      throw Error(fmt::format("sampled clamp motion: zero quaternion at sample {}", i));
  values_.resize(7, n);
  for (int i = 0; i < n; ++i) {
    values_.col(i).head<3>() = d[i];
    values_.col(i).tail<4>() = q_wxyz[i];
  }
  slopes_ = cubic_spline_slopes(t_, values_, SplineEnds::kNatural);
}

RigidPose SampledMotion::at(double t) const {
  // Outside the samples the clamp holds its end pose (zero velocity): scenarios are
  // validated to stay inside, this only keeps a stray evaluation well defined.
  const double tc = std::clamp(t, t_.front(), t_.back());
  const bool held = t != tc;
  const int i =
      std::clamp(static_cast<int>(std::upper_bound(t_.begin(), t_.end(), tc) - t_.begin()) - 1, 0,
                 static_cast<int>(t_.size()) - 2);
  const double h = t_[i + 1] - t_[i], s = (tc - t_[i]) / h;
  const auto y0 = values_.col(i), y1 = values_.col(i + 1);
  const auto m0 = slopes_.col(i), m1 = slopes_.col(i + 1);
  const Eigen::VectorXd v = hermite(y0, m0, y1, m1, s, h, 0);
  Eigen::VectorXd v1 = hermite(y0, m0, y1, m1, s, h, 1), v2 = hermite(y0, m0, y1, m1, s, h, 2);
  if (held) v1.setZero(), v2.setZero();

  RigidPose p;
  p.d = v.head<3>();
  p.ddot = v1.head<3>();
  p.dddot = v2.head<3>();
  const Eigen::Vector4d q = v.tail<4>(), q1 = v1.tail<4>(), q2 = v2.tail<4>();
  // R = M(q)/|q|² is a rotation for any non-zero q; differentiate the quotient.
  const double n = q.squaredNorm(), n1 = 2 * q.dot(q1), n2 = 2 * (q1.dot(q1) + q.dot(q2));
  const Eigen::Matrix3d M = rotation_bilinear(q, q);
  const Eigen::Matrix3d M1 = 2 * rotation_bilinear(q, q1);
  const Eigen::Matrix3d M2 = 2 * rotation_bilinear(q, q2) + 2 * rotation_bilinear(q1, q1);
  p.R = M / n;
  p.Rdot = (M1 - p.R * n1) / n;
  p.Rddot = (M2 - 2 * p.Rdot * n1 - p.R * n2) / n;
  return p;
}

}  // namespace kelvin
