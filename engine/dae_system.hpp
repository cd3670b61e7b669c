#pragma once
/// \file
/// The implicit first-order system handed to IDAS, y = (x, v, z): positions and
/// velocities of the free dofs and the materials' internal variables (none for most
/// models; FemModel::num_internal),
///   F(t, y, y') = [ x' − v ;  M v' + M_fc a_c(t) + r(x, v, z) − p_c(t) − f_ext ;
///                   z' − f(x, z) ] = 0
/// (p_c: the compliant clamps' pull, FemModel::clamp_pull), with the Newton matrix
///   J = ∂F/∂y + c_j ∂F/∂y' = [ c_j I  −I  0 ; K  c_j M + D  K_xz ; −f_x  0  c_j I − f_z ]
/// (SchurSolver solves with it; jacobian() writes it as a 2n × 2n CSC matrix for
/// models without internal variables).
#include <Eigen/Core>
#include <memory>
#include <vector>

#include "engine/fem_model.hpp"

namespace kelvin {

class DaeSystem {
 public:
  explicit DaeSystem(const FemModel& model);

  int size() const { return 2 * n_ + m_; }
  int num_internal() const { return m_; }
  long nnz() const { return 2 * (static_cast<long>(model_.pattern().nnz()) + n_); }
  const FemModel& model() const { return model_; }

  /// Writes the CSC structure (colptr: size()+1 entries, rowind: nnz()).
  template <class Index>
  void structure(Index* colptr, Index* rowind) const;

  /// F(t, y, y'); false when an element is inadmissible (see last_failure()).
  bool residual(double t, const double* y, const double* yp, double* r);
  /// J values in structure() order (models without internal variables).
  bool jacobian(double t, double cj, const double* y, double* values);
  /// Assembles K and D at y (into last_assembly()) and linearises the internal
  /// variables' law (internal()); the blocks of the Newton matrix that SchurSolver
  /// combines.
  bool stiffness_and_damping(double t, const double* y);
  /// f and its linearisation at the state of the last stiffness_and_damping() or
  /// element_tangents() (with param_derivatives, also ∂f/∂q).
  const InternalLinearisation& internal() const { return internal_; }
  /// r += the internal variables' part of ∂F/∂y s at that state: K_xz s_z in the
  /// momentum rows, −f_x s_x − f_z s_z in theirs (the forward sensitivities' residual).
  void add_internal_product(const double* s, double* r) const;
  /// r += −(that part of ∂F/∂y)ᵀ λ: f_xᵀ λz in the position rows, −K_xzᵀ λv + f_zᵀ λz
  /// in the internal ones (the adjoint's residual).
  void add_internal_adjoint_terms(const double* lambda, double* r) const;
  /// Element tangents (with param_derivatives, also dP/dq) at y (the adjoint's
  /// per-state cache); false when an element is inadmissible (the failing element
  /// in tangents()).
  bool element_tangents(double t, const double* y, bool param_derivatives = false);
  const ElementTangents& tangents() const { return tangents_; }
  /// K and D into last_assembly() from tangents(), for SchurSolver.
  void assemble_from_tangents();

  /// y' consistent with y at t: x' = v, v' = M⁻¹(f_ext − r(x, v, z) − M_fc a_c), z' = f.
  bool consistent_derivative(double t, const double* y, double* yp);

  /// out = M⁻¹ rhs over the free dofs (lumped: a division; consistent: sparse LDLᵀ,
  /// factorised once).
  void mass_solve(const double* rhs, double* out);

  const AssemblyOutput& last_assembly() const { return out_; }

 private:
  const FemModel& model_;
  int n_, m_;
  Eigen::Matrix3Xd x_, v_;
  Eigen::VectorXd clamp_inertia_, clamp_pull_, body_load_;
  AssemblyOutput out_;
  ElementTangents tangents_;
  InternalLinearisation internal_;
  std::vector<double> mass_diagonal_;  // lumped mass per free dof
  std::shared_ptr<void> mass_factor_;  // consistent mass LDLᵀ, built on first use
};

template <class Index>
void DaeSystem::structure(Index* colptr, Index* rowind) const {
  const SparsePattern& P = model_.pattern();
  Index k = 0;
  for (int block = 0; block < 2; ++block)
    for (int j = 0; j < n_; ++j) {
      colptr[block * n_ + j] = k;
      rowind[k++] = j;  // c_j I (x columns) or −I (v columns) in the first row block
      for (int p = P.colptr[j]; p < P.colptr[j + 1]; ++p) rowind[k++] = n_ + P.rowind[p];
    }
  colptr[2 * n_] = k;
}

}  // namespace kelvin
