#include "engine/schur_solver.hpp"

#include <klu.h>

#include "engine/error.hpp"

namespace kelvin {

struct SchurSolver::Klu {
  klu_common common;
  klu_symbolic* symbolic = nullptr;
  klu_numeric* numeric = nullptr;
  std::vector<int> colptr, rowind;
  ~Klu() {
    if (numeric) klu_free_numeric(&numeric, &common);
    if (symbolic) klu_free_symbolic(&symbolic, &common);
  }
};

SchurSolver::SchurSolver(DaeSystem& dae)
    : dae_(dae), n_(dae.model().num_dofs()), klu_(std::make_unique<Klu>()) {
  const SparsePattern& P = dae.model().pattern();
  klu_->colptr = P.colptr;
  klu_->rowind = P.rowind;
  klu_defaults(&klu_->common);
  klu_->common.ordering = 0;  // AMD on S + Sᵀ: S has the symmetric FEM pattern
  klu_->symbolic = klu_analyze(n_, klu_->colptr.data(), klu_->rowind.data(), &klu_->common);
  if (!klu_->symbolic) throw Error("KLU could not analyse the stiffness pattern");
  S_.resize(P.nnz());
  rhs_.resize(n_);
  r1_.resize(n_);
}

SchurSolver::~SchurSolver() = default;

bool SchurSolver::assemble(double t, double cj, const double* y) {
  if (!dae_.stiffness_and_damping(t, y)) return false;
  assemble_from_last(cj);
  return true;
}

void SchurSolver::assemble_from_last(double cj) {
  const AssemblyOutput& out = dae_.last_assembly();
  const std::vector<double>& M = dae_.model().mass();
  for (size_t k = 0; k < S_.size(); ++k) S_[k] = out.K[k] + cj * out.D[k] + cj * cj * M[k];
  K_ = out.K;
  D_ = out.D;
  cj_ = cj;
}

bool SchurSolver::factorize() {
  auto& k = *klu_;
  // Refactor keeps the pivot order of the first factorisation; fall back to a full
  // factorisation when it turns out poor (tiny reciprocal pivot growth).
  if (k.numeric &&
      klu_refactor(k.colptr.data(), k.rowind.data(), S_.data(), k.symbolic, k.numeric, &k.common)) {
    if (klu_rcond(k.symbolic, k.numeric, &k.common) && k.common.rcond > 1e-14) return true;
  }
  if (k.numeric) klu_free_numeric(&k.numeric, &k.common);
  k.numeric = klu_factor(k.colptr.data(), k.rowind.data(), S_.data(), k.symbolic, &k.common);
  return k.numeric != nullptr;
}

void SchurSolver::solve(const double* b, double* x) {
  const SparsePattern& P = dae_.model().pattern();
  const std::vector<double>& M = dae_.model().mass();
  r1_ = Eigen::Map<const Eigen::VectorXd>(b, n_);
  rhs_ = Eigen::Map<const Eigen::VectorXd>(b + n_, n_);
  for (int c = 0; c < n_; ++c)
    for (int p = P.colptr[c]; p < P.colptr[c + 1]; ++p)
      rhs_[P.rowind[p]] += (cj_ * M[p] + D_[p]) * r1_[c];
  klu_solve(klu_->symbolic, klu_->numeric, n_, 1, rhs_.data(), &klu_->common);
  for (int i = 0; i < n_; ++i) {
    x[i] = rhs_[i];
    x[n_ + i] = cj_ * rhs_[i] - r1_[i];
  }
}

void SchurSolver::solve_adjoint(const double* b, double* x) {
  const SparsePattern& P = dae_.model().pattern();
  const double cB = -cj_;
  r1_ = Eigen::Map<const Eigen::VectorXd>(b, n_);
  rhs_ = cB * Eigen::Map<const Eigen::VectorXd>(b + n_, n_) - r1_;
  klu_tsolve(klu_->symbolic, klu_->numeric, n_, 1, rhs_.data(), &klu_->common);
  for (int c = 0; c < n_; ++c) {
    double ktb = 0;  // (Kᵀ x₂)_c
    for (int p = P.colptr[c]; p < P.colptr[c + 1]; ++p) ktb += K_[p] * rhs_[P.rowind[p]];
    x[c] = (r1_[c] + ktb) / cB;
    x[n_ + c] = rhs_[c];
  }
}

}  // namespace kelvin
