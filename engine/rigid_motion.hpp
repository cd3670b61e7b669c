#pragma once
// Rigid motions that clamps follow: x(t) = R(t) X + d(t) for a clamped node at
// rest position X. Poses carry first and second time derivatives so that clamp
// velocities (viscous forces) and accelerations (consistent mass coupling) are exact.
#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

namespace kelvin {

struct RigidPose {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity(), Rdot = Eigen::Matrix3d::Zero(),
                  Rddot = Eigen::Matrix3d::Zero();
  Eigen::Vector3d d = Eigen::Vector3d::Zero(), ddot = Eigen::Vector3d::Zero(),
                  dddot = Eigen::Vector3d::Zero();

  Eigen::Vector3d position(const Eigen::Vector3d& X) const { return R * X + d; }
  Eigen::Vector3d velocity(const Eigen::Vector3d& X) const { return Rdot * X + ddot; }
  Eigen::Vector3d acceleration(const Eigen::Vector3d& X) const { return Rddot * X + dddot; }
};

class RigidMotion {
 public:
  virtual ~RigidMotion() = default;
  virtual RigidPose at(double t) const = 0;
  /// Last time at which the motion is defined (infinity for scripted motions).
  virtual double end_time() const;
};

/// A clamp that does not move.
class FixedMotion : public RigidMotion {
 public:
  RigidPose at(double) const override { return {}; }
};

/// A clamp held at a constant offset from rest (a probe pressed to a depth).
class TranslatedMotion : public RigidMotion {
 public:
  explicit TranslatedMotion(const Eigen::Vector3d& d) { pose_.d = d; }
  RigidPose at(double) const override { return pose_; }

 private:
  RigidPose pose_;
};

/// One term a sin(2π f t + φ) of a scripted motion.
struct Sinusoid {
  double amplitude = 0;  // m for translation (times `direction`), rad for rotation
  double frequency = 0;  // Hz
  double phase = 0;      // rad
  Eigen::Vector3d direction = Eigen::Vector3d::UnitX();  // translation direction (unit)
};

/// Translation d(t) = Σ direction_k a_k sin(2π f_k t + φ_k), plus a rotation by
/// angle θ(t) = Σ a_k sin(2π f_k t + φ_k) about a fixed `axis` through `center`.
class SinusoidMotion : public RigidMotion {
 public:
  SinusoidMotion(std::vector<Sinusoid> translation, std::vector<Sinusoid> rotation,
                 Eigen::Vector3d axis, Eigen::Vector3d center);
  RigidPose at(double t) const override;

 private:
  std::vector<Sinusoid> translation_, rotation_;
  Eigen::Vector3d axis_, center_;
};

/// Measured clamp motion: rows (t, translation, unit quaternion w,x,y,z) about the
/// world origin. Translation and quaternion components are interpolated by natural
/// cubic splines (C2, so accelerations exist); the quaternion is normalised through
/// R = M(q)/|q|², whose derivatives are taken exactly.
class SampledMotion : public RigidMotion {
 public:
  SampledMotion(std::vector<double> t, std::vector<Eigen::Vector3d> d,
                std::vector<Eigen::Vector4d> q_wxyz);
  RigidPose at(double t) const override;
  double end_time() const override { return t_.back(); }
  double start_time() const { return t_.front(); }

 private:
  std::vector<double> t_;
  Eigen::MatrixXd values_;  // 7 × n samples (d, q)
  Eigen::MatrixXd slopes_;  // spline slopes at the samples, 7 × n
};

}  // namespace kelvin
