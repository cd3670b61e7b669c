#pragma once
/// \file
/// The force a rigid clamp exerts on the body at rest (v = 0): a probe pressed to a
/// depth measures it. At a held node a, r_a = m_a g + f_a, so
///   R = Σ_{a ∈ clamp} (r_a(x) − m_a g),
/// r the internal force, m_a g the node's weight. Its position derivative enters an
/// adjoint's load ((∂R/∂x)ᵀ w over the free dofs); its parameter derivative is the
/// held rows of ∂r/∂q (ParamDerivatives' dR at the held dofs).
#include <Eigen/Core>
#include <vector>

#include "engine/fem_model.hpp"

namespace kelvin {

class ClampReaction {
 public:
  ClampReaction(const FemModel& model, int clamp);

  /// True when the clamp holds `node`.
  bool holds(int node) const { return held_[node]; }
  /// Σ m_a g over the held nodes: R + weight() is their internal force.
  const Eigen::Vector3d& weight() const { return weight_; }
  /// R at full positions x; false (element in failed_element) when a material
  /// rejects x.
  bool force(const Eigen::Matrix3Xd& x, Eigen::Vector3d& R) const;
  /// (∂R/∂x_free)ᵀ into `rows` (free dofs × 3); false when a material rejects x.
  bool position_rows(const Eigen::Matrix3Xd& x,
                     Eigen::Matrix<double, Eigen::Dynamic, 3>& rows) const;
  /// Adds (∂R/∂x_free)ᵀ w into `out` (free dofs); false when a material rejects x.
  bool add_position_adjoint(const Eigen::Matrix3Xd& x, const Eigen::Vector3d& w,
                            Eigen::VectorXd& out) const;

  mutable int failed_element = -1;

 private:
  const FemModel& model_;
  std::vector<bool> held_;
  std::vector<int> elements_;  // with at least one held node
  Eigen::Vector3d weight_;     // Σ m_a g over the held nodes
};

}  // namespace kelvin
