#pragma once
/// \file
/// A body-force field per unit mass, a(X, t) = Σₖ φₖ(t) aₖ(e): element-constant
/// accelerations aₖ at K knots in time, φₖ the piecewise-linear hats on knots
/// tₖ = start + (k + 1) h, h = (end − start)/(K + 1). The field is zero at the start,
/// so the static initial state does not depend on it, and at the end, where a force
/// would have no time to move a marker (a knot there is barely observable). It is what a fit adds to make the
/// model follow a capture (Wang/Kry's control forces): zero unless fitted.
#include <Eigen/Core>
#include <array>

namespace kelvin {

class BodyForceField {
 public:
  /// K knots over [start, end] for ne elements, all accelerations zero.
  void configure(double start, double end, int knots, int elements);
  bool active() const { return knots_ > 0; }
  int knots() const { return knots_; }
  double knot_time(int k) const { return start_ + (k + 1) * spacing_; }
  /// φₖ(t).
  double hat(int k, double t) const;
  /// aₖ of axis i (0, 1, 2) in element e, m/s².
  double& value(int axis, int k, int e) { return accel_[axis](k, e); }
  double value(int axis, int k, int e) const { return accel_[axis](k, e); }
  /// a(e, t).
  Eigen::Vector3d at(int e, double t) const;

 private:
  double start_ = 0, spacing_ = 0;
  int knots_ = 0;
  std::array<Eigen::MatrixXd, 3> accel_;  // knots × elements per axis
};

}  // namespace kelvin
