#include "engine/dae_system.hpp"

#include <Eigen/SparseCholesky>

#include "base/error.hpp"

namespace kelvin {

DaeSystem::DaeSystem(const FemModel& model)
    : model_(model), n_(model.num_dofs()), m_(model.num_internal()) {}

bool DaeSystem::residual(double t, const double* y, const double* yp, double* r) {
  model_.expand(t, y, y + n_, x_, v_);
  const double* z = m_ ? y + 2 * n_ : nullptr;
  if (!model_.assemble(x_, v_, {}, out_, z)) return false;
  if (m_) {
    if (!model_.linearise_internal(x_, v_, z, 0, internal_)) return false;
    for (int k = 0; k < m_; ++k) r[2 * n_ + k] = yp[2 * n_ + k] - internal_.rate[k];
  }
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
  const double* z = m_ ? y + 2 * n_ : nullptr;
  return model_.assemble(x_, v_, req, out_, z) &&
         (!m_ || model_.linearise_internal(x_, v_, z, kTangent, internal_));
}

bool DaeSystem::element_tangents(double t, const double* y, bool param_derivatives) {
  model_.expand(t, y, y + n_, x_, v_);
  const double* z = m_ ? y + 2 * n_ : nullptr;
  const unsigned request = kTangent | (param_derivatives ? kParamDerivative : 0u);
  return model_.element_tangents(x_, v_, tangents_, param_derivatives, z) &&
         (!m_ || model_.linearise_internal(x_, v_, z, request, internal_));
}

void DaeSystem::assemble_from_tangents() {
  model_.assemble_tangents(tangents_, out_.K, out_.D, out_.slots);
}

bool DaeSystem::jacobian(double t, double cj, const double* y, double* val) {
  if (m_) throw Error("the CSC Newton matrix is not written for materials with internal variables");
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

void DaeSystem::add_internal_product(const double* s, double* r) const {
  const auto& blocks = model_.internal_blocks();
  for (size_t k = 0; k < blocks.size(); ++k) {
    const InternalBlock& b = blocks[k];
    const Eigen::Map<const Eigen::VectorXd> sz(s + 2 * n_ + b.offset, b.size);
    // A branch without stress (a screened one at g = 0) owes the forces nothing.
    if (internal_.coupled[k]) model_.add_element_values(b.element, internal_.Kxz[k] * sz, r + n_);
    // Accumulated in place: no heap temporary per block and sensitivity.
    Eigen::Map<Eigen::VectorXd> rz(r + 2 * n_ + b.offset, b.size);
    rz.noalias() -= internal_.fx[k] * model_.element_values(b.element, s);
    rz.noalias() -= internal_.fz[k] * sz;
  }
}

void DaeSystem::add_internal_adjoint_terms(const double* lambda, double* r) const {
  const auto& blocks = model_.internal_blocks();
  for (size_t k = 0; k < blocks.size(); ++k) {
    const InternalBlock& b = blocks[k];
    const Eigen::Map<const Eigen::VectorXd> lz(lambda + 2 * n_ + b.offset, b.size);
    model_.add_element_values(b.element, internal_.fx[k].transpose() * lz, r);
    Eigen::Map<Eigen::VectorXd> rz(r + 2 * n_ + b.offset, b.size);
    rz.noalias() += internal_.fz[k].transpose() * lz;
    if (internal_.coupled[k])
      rz.noalias() -= internal_.Kxz[k].transpose() * model_.element_values(b.element, lambda + n_);
  }
}

bool DaeSystem::consistent_derivative(double t, const double* y, double* yp) {
  model_.expand(t, y, y + n_, x_, v_);
  const double* z = m_ ? y + 2 * n_ : nullptr;
  if (!model_.assemble(x_, v_, {}, out_, z)) return false;
  if (m_) {
    if (!model_.linearise_internal(x_, v_, z, 0, internal_)) return false;
    for (int k = 0; k < m_; ++k) yp[2 * n_ + k] = internal_.rate[k];
  }
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
