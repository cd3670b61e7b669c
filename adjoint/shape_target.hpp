#pragma once
/// \file
/// A target shape at one time (Real2Sim §5, Fig. 10): the objective term
///   Φ_k = w/2 Σ_{n,a} (x_{n,a}(t_k) − x̄_{n,a})²
/// over the selected nodes n and the axes a that count (all three for a target
/// given as offsets of the rest positions, one for a flat face). A value at a
/// fixed time, not an integral: the adjoint's λx jumps by ∂Φ_k/∂x there.
#include <Eigen/Core>
#include <cmath>
#include <string>
#include <vector>

#include "engine/fem_model.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {

class ShapeTarget {
 public:
  ShapeTarget(const ShapeTargetSpec& spec, const Mesh& mesh);

  const std::string& name() const { return name_; }
  double time() const { return time_; }
  double weight() const { return weight_; }
  /// Coordinates that count: the RMS distance is sqrt(2Φ_k / (w · this)).
  int coordinates() const { return static_cast<int>(nodes_.size()) * (axis_ < 0 ? 3 : 1); }
  double rms(double phi) const { return std::sqrt(2 * phi / (weight_ * coordinates())); }

  /// Φ_k at the full nodal positions x (3 × nodes).
  double value(const Eigen::Matrix3Xd& x) const;
  /// ∂Φ_k/∂x over the free dofs of `model`, added to grad (clamped nodes move as
  /// prescribed: their share of Φ_k does not depend on the parameters).
  void add_gradient(const FemModel& model, const Eigen::Matrix3Xd& x, double* grad) const;

 private:
  std::string name_;
  double time_ = 0, weight_ = 1;
  std::vector<int> nodes_;
  Eigen::Matrix3Xd target_;  // x̄ per selected node (only row axis_ is used when ≥ 0)
  int axis_ = -1;
};

}  // namespace kelvin
