#include "adjoint/shape_target.hpp"

namespace kelvin {

ShapeTarget::ShapeTarget(const ShapeTargetSpec& spec, const Mesh& mesh)
    : name_(spec.name),
      time_(spec.time),
      weight_(spec.weight),
      nodes_(spec.nodes),
      target_(3, static_cast<Eigen::Index>(spec.nodes.size())),
      axis_(spec.plane_axis) {
  for (size_t k = 0; k < nodes_.size(); ++k) {
    const auto c = static_cast<Eigen::Index>(k);
    target_.col(c) = spec.positions.cols()
                         ? Eigen::Vector3d(spec.positions.col(c))
                         : Eigen::Vector3d(mesh.nodes.col(nodes_[k]) + spec.offset);
    if (axis_ >= 0) target_(axis_, c) = spec.plane_at;
  }
}

double ShapeTarget::value(const Eigen::Matrix3Xd& x) const {
  double sum = 0;
  for (size_t k = 0; k < nodes_.size(); ++k) {
    const Eigen::Vector3d r = x.col(nodes_[k]) - target_.col(static_cast<Eigen::Index>(k));
    sum += axis_ < 0 ? r.squaredNorm() : r[axis_] * r[axis_];
  }
  return 0.5 * weight_ * sum;
}

void ShapeTarget::add_gradient(const FemModel& model, const Eigen::Matrix3Xd& x,
                               double* grad) const {
  for (size_t k = 0; k < nodes_.size(); ++k)
    for (int a = 0; a < 3; ++a) {
      if (axis_ >= 0 && a != axis_) continue;
      if (const int d = model.dof(nodes_[k], a); d >= 0)
        grad[d] += weight_ * (x(a, nodes_[k]) - target_(a, static_cast<Eigen::Index>(k)));
    }
}

}  // namespace kelvin
