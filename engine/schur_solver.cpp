#include "engine/schur_solver.hpp"

#include <cholmod.h>
#include <klu.h>

#include <Eigen/LU>
#include <algorithm>

#include "base/error.hpp"

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

/// CHOLMOD's factor of the symmetric part, and dense views and workspaces that its
/// solves reuse (cholmod_solve2 allocates them once).
struct SchurSolver::Cholmod {
  cholmod_common common;
  cholmod_sparse A{};  // view of the pattern with S_sym_ (lower triangle read)
  cholmod_factor* L = nullptr;
  cholmod_dense B{}, *X = nullptr, *Y = nullptr, *E = nullptr;
  Eigen::VectorXd b;
  Cholmod() {
    cholmod_start(&common);
    common.print = 0;  // an indefinite S is expected now and then: KLU takes it
    // Simplicial LLᵀ: with Debian's reference BLAS the supernodal factor (CHOLMOD's
    // own choice from 1.3k dofs up) factorised 2.2× and solved 2.2× slower on 1.3k
    // dofs, and solved 1.2× slower on 14.6k.
    common.supernodal = CHOLMOD_SIMPLICIAL;
    common.final_ll = 1;
  }
  ~Cholmod() {
    for (cholmod_dense** d : {&X, &Y, &E})
      if (*d) cholmod_free_dense(d, &common);
    if (L) cholmod_free_factor(&L, &common);
    cholmod_finish(&common);
  }
};

SchurSolver::SchurSolver(DaeSystem& dae)
    : dae_(dae),
      n_(dae.model().num_dofs()),
      klu_(std::make_unique<Klu>()),
      cholmod_(std::make_unique<Cholmod>()) {
  const SparsePattern& P = dae.model().pattern();
  klu_->colptr = P.colptr;
  klu_->rowind = P.rowind;
  klu_defaults(&klu_->common);
  klu_->common.ordering = 0;  // AMD on S + Sᵀ: S has the symmetric FEM pattern
  klu_->symbolic = klu_analyze(n_, klu_->colptr.data(), klu_->rowind.data(), &klu_->common);
  if (!klu_->symbolic) throw Error("KLU could not analyse the stiffness pattern");
  S_.resize(P.nnz());
  S_sym_.resize(P.nnz());
  rhs_.resize(n_);
  r1_.resize(n_);
  transpose_.resize(P.nnz());
  for (int c = 0; c < n_; ++c)
    for (int k = P.colptr[c]; k < P.colptr[c + 1]; ++k) transpose_[k] = P.find(c, P.rowind[k]);

  auto& ch = *cholmod_;
  ch.A.nrow = ch.A.ncol = n_;
  ch.A.nzmax = P.nnz();
  ch.A.p = klu_->colptr.data();
  ch.A.i = klu_->rowind.data();
  ch.A.x = S_sym_.data();
  ch.A.stype = -1;  // symmetric, lower triangle used
  ch.A.itype = CHOLMOD_INT;
  ch.A.xtype = CHOLMOD_REAL;
  ch.A.dtype = CHOLMOD_DOUBLE;
  ch.A.sorted = 1;
  ch.A.packed = 1;
  ch.L = cholmod_analyze(&ch.A, &ch.common);
  if (!ch.L) throw Error("CHOLMOD could not analyse the stiffness pattern");
  ch.b.resize(n_);
  ch.B.nrow = n_;
  ch.B.ncol = 1;
  ch.B.nzmax = n_;
  ch.B.d = n_;
  ch.B.x = ch.b.data();
  ch.B.xtype = CHOLMOD_REAL;
  ch.B.dtype = CHOLMOD_DOUBLE;
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
  const FemModel& model = dae_.model();
  const auto& blocks = model.internal_blocks();
  if (!blocks.empty()) {
    const InternalLinearisation& lin = dae_.internal();
    A_inv_.resize(blocks.size());
    Kxz_ = lin.Kxz;
    fx_ = lin.fx;
    coupled_ = lin.coupled;
    // Sized for the largest block once: blocks of several sizes (a plugin's beside a
    // Maxwell branch) then share it without reallocating in the solves.
    int largest = 0;
    for (const auto& blk : blocks) largest = std::max(largest, blk.size);
    block_.resize(largest);
    for (size_t b = 0; b < blocks.size(); ++b) {
      const int m = blocks[b].size;
      A_inv_[b] = (cj * Eigen::MatrixXd::Identity(m, m) - lin.fz[b]).inverse();
      if (!coupled_[b]) continue;  // a branch without stress adds nothing to S
      const Eigen::Matrix<double, 12, 12> C = Kxz_[b] * A_inv_[b] * fx_[b];
      model.scatter_element_matrix(blocks[b].element, C, S_.data());
    }
  }
  for (size_t k = 0; k < S_.size(); ++k) S_sym_[k] = 0.5 * (S_[k] + S_[transpose_[k]]);
  K_ = out.K;
  D_ = out.D;
  cj_ = cj;
}

bool SchurSolver::factorize() {
  auto& ch = *cholmod_;
  if (cholmod_factorize(&ch.A, ch.L, &ch.common) && ch.common.status == CHOLMOD_OK) {
    lu_active_ = false;
    return true;
  }
  lu_active_ = true;
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
  const FemModel& model = dae_.model();
  const SparsePattern& P = model.pattern();
  const std::vector<double>& M = model.mass();
  const auto& blocks = model.internal_blocks();
  r1_ = Eigen::Map<const Eigen::VectorXd>(b, n_);
  rhs_ = Eigen::Map<const Eigen::VectorXd>(b + n_, n_);
  for (int c = 0; c < n_; ++c)
    for (int p = P.colptr[c]; p < P.colptr[c + 1]; ++p)
      rhs_[P.rowind[p]] += (cj_ * M[p] + D_[p]) * r1_[c];
  const double* r3 = b + 2 * n_;
  for (size_t k = 0; k < blocks.size(); ++k) {  // − K_xz A⁻¹ r₃
    if (!coupled_[k]) continue;
    const InternalBlock& blk = blocks[k];
    auto v = block_.head(blk.size);
    v.noalias() = A_inv_[k] * Eigen::Map<const Eigen::VectorXd>(r3 + blk.offset, blk.size);
    model.add_element_values(blk.element, -Kxz_[k] * v, rhs_.data());
  }
  apply_inverse(rhs_.data(), false);
  // x₃ before x₁, x₂: the right-hand side may alias the solution (block by block,
  // x₃'s block k overwrites r₃'s block k only).
  for (size_t k = 0; k < blocks.size(); ++k) {  // x₃ = A⁻¹(r₃ + f_x x₁)
    const InternalBlock& blk = blocks[k];
    auto v = block_.head(blk.size);
    v = Eigen::Map<const Eigen::VectorXd>(r3 + blk.offset, blk.size);
    v.noalias() += fx_[k] * model.element_values(blk.element, rhs_.data());
    Eigen::Map<Eigen::VectorXd>(x + 2 * n_ + blk.offset, blk.size).noalias() = A_inv_[k] * v;
  }
  for (int i = 0; i < n_; ++i) {
    x[i] = rhs_[i];
    x[n_ + i] = cj_ * rhs_[i] - r1_[i];
  }
}

void SchurSolver::solve_adjoint(const double* b, double* x) {
  const FemModel& model = dae_.model();
  const SparsePattern& P = model.pattern();
  const auto& blocks = model.internal_blocks();
  const double cB = -cj_;
  r1_ = Eigen::Map<const Eigen::VectorXd>(b, n_);
  rhs_ = cB * Eigen::Map<const Eigen::VectorXd>(b + n_, n_) - r1_;
  const double* r3 = b + 2 * n_;
  for (size_t k = 0; k < blocks.size(); ++k) {  // − f_xᵀ A⁻ᵀ r₃
    const InternalBlock& blk = blocks[k];
    auto v = block_.head(blk.size);
    v.noalias() =
        A_inv_[k].transpose() * Eigen::Map<const Eigen::VectorXd>(r3 + blk.offset, blk.size);
    model.add_element_values(blk.element, -fx_[k].transpose() * v, rhs_.data());
  }
  apply_inverse(rhs_.data(), true);
  // x₃ = −A⁻ᵀ(r₃ + K_xzᵀ x₂), and f_xᵀ x₃ for x₁, before x is written (it may alias b).
  fx3_.setZero(n_);
  z_.resize(blocks.size());
  for (size_t k = 0; k < blocks.size(); ++k) {
    const InternalBlock& blk = blocks[k];
    auto v = block_.head(blk.size);
    v = Eigen::Map<const Eigen::VectorXd>(r3 + blk.offset, blk.size);
    if (coupled_[k])
      v.noalias() += Kxz_[k].transpose() * model.element_values(blk.element, rhs_.data());
    z_[k].resize(blk.size);
    z_[k].noalias() = -A_inv_[k].transpose() * v;
    model.add_element_values(blk.element, fx_[k].transpose() * z_[k], fx3_.data());
  }
  for (size_t k = 0; k < blocks.size(); ++k)
    Eigen::Map<Eigen::VectorXd>(x + 2 * n_ + blocks[k].offset, blocks[k].size) = z_[k];
  for (int c = 0; c < n_; ++c) {
    double ktb = 0;  // (Kᵀ x₂)_c
    for (int p = P.colptr[c]; p < P.colptr[c + 1]; ++p) ktb += K_[p] * rhs_[P.rowind[p]];
    x[c] = (r1_[c] + ktb - fx3_[c]) / cB;
    x[n_ + c] = rhs_[c];
  }
}

void SchurSolver::apply_inverse(double* x, bool transposed) {
  if (lu_active_) {
    if (transposed)
      klu_tsolve(klu_->symbolic, klu_->numeric, n_, 1, x, &klu_->common);
    else
      klu_solve(klu_->symbolic, klu_->numeric, n_, 1, x, &klu_->common);
    return;
  }
  auto& ch = *cholmod_;  // symmetric: the transpose is the same solve
  std::copy(x, x + n_, ch.b.data());
  if (!cholmod_solve2(CHOLMOD_A, ch.L, &ch.B, nullptr, &ch.X, nullptr, &ch.Y, &ch.E, &ch.common))
    throw Error("CHOLMOD could not solve with the Newton matrix");
  const double* sol = static_cast<const double*>(ch.X->x);
  std::copy(sol, sol + n_, x);
}

}  // namespace kelvin
