#include "engine/dae_system.hpp"

#include <Eigen/SparseCholesky>

namespace kelvin {

DaeSystem::DaeSystem(const FemModel& model) : model_(model), n_(model.num_dofs()) {}

bool DaeSystem::residual(double t, const double* y, const double* yp, double* r) {
  model_.expand(t, y, y + n_, x_, v_);
  if (!model_.assemble(x_, v_, {}, out_)) return false;
  model_.clamp_inertia(t, clamp_inertia_);
  model_.clamp_pull(t, true, clamp_pull_);
  model_.body_force_load(t, body_load_);
  for (int i = 0; i < n_; ++i) r[i] = yp[i] - y[n_ + i];
  double* rv = r + n_;
  for (int i = 0; i < n_; ++i)
    rv[i] = out_.force[i] + clamp_inertia_[i] - clamp_pull_[i] - body_load_[i] -
            model_.external_force()[i];
  model_.mass_multiply(yp + n_, rv);
  return true;
}

bool DaeSystem::stiffness_and_damping(double t, const double* y) {
  model_.expand(t, y, y + n_, x_, v_);
  AssemblyRequest req;
  req.force = false;
  req.stiffness = true;
  req.damping = true;
  return model_.assemble(x_, v_, req, out_);
}

bool DaeSystem::element_tangents(double t, const double* y, bool param_derivatives) {
  model_.expand(t, y, y + n_, x_, v_);
  return model_.element_tangents(x_, v_, tangents_, param_derivatives);
}

void DaeSystem::assemble_from_tangents() {
  model_.assemble_tangents(tangents_, out_.K, out_.D, out_.slots);
}

bool DaeSystem::jacobian(double t, double cj, const double* y, double* val) {
  if (!stiffness_and_damping(t, y)) return false;
  const SparsePattern& P = model_.pattern();
  const std::vector<double>& M = model_.mass();
  long k = 0;
  for (int j = 0; j < n_; ++j) {
    val[k++] = cj;
    for (int p = P.colptr[j]; p < P.colptr[j + 1]; ++p) val[k++] = out_.K[p];
  }
  for (int j = 0; j < n_; ++j) {
    val[k++] = -1.0;
    for (int p = P.colptr[j]; p < P.colptr[j + 1]; ++p) val[k++] = cj * M[p] + out_.D[p];
  }
  return true;
}

bool DaeSystem::consistent_derivative(double t, const double* y, double* yp) {
  model_.expand(t, y, y + n_, x_, v_);
  if (!model_.assemble(x_, v_, {}, out_)) return false;
  model_.clamp_inertia(t, clamp_inertia_);
  model_.clamp_pull(t, true, clamp_pull_);
  model_.body_force_load(t, body_load_);
  const Eigen::VectorXd rhs =
      model_.external_force() + clamp_pull_ + body_load_ - out_.force - clamp_inertia_;
  for (int i = 0; i < n_; ++i) yp[i] = y[n_ + i];
  mass_solve(rhs.data(), yp + n_);
  return true;
}

void DaeSystem::mass_solve(const double* rhs, double* out) {
  using Factor = Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>>;
  const SparsePattern& P = model_.pattern();
  Eigen::Map<const Eigen::VectorXd> b(rhs, n_);
  Eigen::Map<Eigen::VectorXd> x(out, n_);
  if (model_.lumped_mass()) {
    if (mass_diagonal_.empty()) {
      mass_diagonal_.resize(n_);
      for (int j = 0; j < n_; ++j) mass_diagonal_[j] = model_.mass()[P.find(j, j)];
    }
    for (int j = 0; j < n_; ++j) x[j] = b[j] / mass_diagonal_[j];
    return;
  }
  if (!mass_factor_) mass_factor_ = std::make_shared<Factor>(to_sparse_matrix(P, model_.mass()));
  x = static_cast<Factor*>(mass_factor_.get())->solve(b);
}

}  // namespace kelvin
