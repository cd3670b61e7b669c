#include "engine/body_force.hpp"

#include <algorithm>
#include <cmath>

#include "base/error.hpp"

namespace kelvin {

void BodyForceField::configure(double start, double end, int knots, int elements) {
  if (knots < 1 || !(end > start))
    throw Error("a body-force field needs at least one knot and a time span of positive length");
  if (knots == knots_ && start == start_ && spacing_ == (end - start) / (knots + 1) &&
      accel_[0].cols() == elements)
    return;
  start_ = start;
  spacing_ = (end - start) / (knots + 1);
  knots_ = knots;
  for (auto& a : accel_) a = Eigen::MatrixXd::Zero(knots, elements);
}

double BodyForceField::hat(int k, double t) const {
  return std::max(0.0, 1.0 - std::abs(t - knot_time(k)) / spacing_);
}

Eigen::Vector3d BodyForceField::at(int e, double t) const {
  Eigen::Vector3d a = Eigen::Vector3d::Zero();
  if (!active()) return a;
  // At most two hats are non-zero at t.
  const double below = std::floor((t - start_) / spacing_) - 1;  // the knot at or below t
  const int k0 = static_cast<int>(std::clamp(below, 0.0, knots_ - 1.0));
  for (int k = k0; k <= std::min(k0 + 1, knots_ - 1); ++k)
    if (const double w = hat(k, t); w > 0)
      for (int i = 0; i < 3; ++i) a[i] += w * accel_[i](k, e);
  return a;
}

}  // namespace kelvin
