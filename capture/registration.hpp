#pragma once
/// \file
/// The rigid transform from a capture's frame to the model's, by least squares over
/// named correspondences (Kabsch: the SVD of the centred cross-covariance, with the
/// reflection removed), and its residual per marker.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace kelvin {

struct Registration {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Vector3d apply(const Eigen::Vector3d& x) const { return R * x + t; }
  std::vector<std::string> names;  // the markers it was fitted to
  Eigen::Matrix3Xd residual;       // model − R·capture − t, per marker (m)
  double rms() const;              // of the residual lengths (m)
};

/// R, t minimising Σ |R from_i + t − to_i|²; at least three points not on one line.
Registration fit_registration(const Eigen::Matrix3Xd& from, const Eigen::Matrix3Xd& to,
                              std::vector<std::string> names);

}  // namespace kelvin
