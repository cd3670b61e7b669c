#include "engine/clamp_reaction.hpp"

#include "engine/element.hpp"

namespace kelvin {

ClampReaction::ClampReaction(const FemModel& model, int clamp)
    : model_(model), held_(model.mesh().num_nodes(), false) {
  for (int a : model.clamps().at(clamp).nodes) held_[a] = true;
  double mass = 0;  // row sums of the consistent mass, equal to the lumped one
  for (int e = 0; e < model.mesh().num_tets(); ++e) {
    const TetElement& el = model.elements()[e];
    int held = 0;
    for (int a = 0; a < 4; ++a) held += held_[el.nodes[a]];
    if (held == 0) continue;
    elements_.push_back(e);
    mass += held * model.density()[e] * el.volume / 4;
  }
  weight_ = mass * model.gravity();
}

bool ClampReaction::force(const Eigen::Matrix3Xd& x, Eigen::Vector3d& R) const {
  const Eigen::Matrix3Xd v = Eigen::Matrix3Xd::Zero(3, x.cols());
  ElementResponse resp;
  R = -weight_;
  for (int e : elements_) {
    if (!model_.evaluate_element(e, x, v, kStress, resp)) {
      failed_element = e;
      return false;
    }
    const TetElement& el = model_.elements()[e];
    const Eigen::Matrix<double, 3, 4> f = el.volume * resp.P * el.G;
    for (int a = 0; a < 4; ++a)
      if (held_[el.nodes[a]]) R += f.col(a);
  }
  return true;
}

bool ClampReaction::position_rows(const Eigen::Matrix3Xd& x,
                                  Eigen::Matrix<double, Eigen::Dynamic, 3>& rows) const {
  rows.setZero(model_.num_dofs(), 3);
  const Eigen::Matrix3Xd v = Eigen::Matrix3Xd::Zero(3, x.cols());
  ElementResponse resp;
  for (int e : elements_) {
    if (!model_.evaluate_element(e, x, v, kStress | kTangent, resp)) {
      failed_element = e;
      return false;
    }
    const TetElement& el = model_.elements()[e];
    Eigen::Matrix<double, 12, 12> Ke = Eigen::Matrix<double, 12, 12>::Zero();
    accumulate_element_matrix(el, resp.dPdF, 1.0, Ke);
    // ∂R_i/∂x_(b,j) sums the held rows (a, i) of Ke.
    Eigen::Matrix<double, 3, 12> held_rows = Eigen::Matrix<double, 3, 12>::Zero();
    for (int a = 0; a < 4; ++a)
      if (held_[el.nodes[a]]) held_rows += Ke.middleRows<3>(3 * a);
    for (int b = 0; b < 4; ++b)
      for (int j = 0; j < 3; ++j)
        if (const int d = model_.dof(el.nodes[b], j); d >= 0)
          rows.row(d) += held_rows.col(3 * b + j).transpose();
  }
  return true;
}

bool ClampReaction::add_position_adjoint(const Eigen::Matrix3Xd& x, const Eigen::Vector3d& w,
                                         Eigen::VectorXd& out) const {
  Eigen::Matrix<double, Eigen::Dynamic, 3> rows;
  if (!position_rows(x, rows)) return false;
  out += rows * w;
  return true;
}

}  // namespace kelvin
