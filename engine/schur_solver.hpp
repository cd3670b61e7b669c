#pragma once
/// \file
/// Direct solver for the IDAS Newton systems of the DAE (dae_system.hpp),
///   [ c_j I      −I       ] [a]   [r₁]
///   [ K      c_j M + D    ] [b] = [r₂],
/// by eliminating the velocity block: b = c_j a − r₁ and
///   S a = r₂ + (c_j M + D) r₁,   S = K + c_j D + c_j² M,
/// an n × n system with the FEM sparsity pattern. Half the unknowns and a fraction
/// of the fill of factorising the 2n × 2n matrix (bench_forward).
///
/// Internal variables z (FemModel::num_internal; DaeSystem's third block) are
/// eliminated element by element first: their rows c_j z − f_z z − f_x x = r₃ give
/// z = A⁻¹(r₃ + f_x x), A = c_j I − f_z, and S gains K_xz A⁻¹ f_x in each element's
/// block (a relaxing branch's stiffness, scaled by how far it relaxes in a step).
///
/// S is symmetric but for the viscous stresses' dependence on F (a small part of K),
/// and positive definite while c_j² M dominates. Its symmetric part is factorised by
/// CHOLMOD (simplicial Cholesky), which IDAS's
/// modified Newton iteration takes as its Newton matrix; where that part is not
/// positive definite (large steps on a compressed or buckling body) S itself is
/// factorised by KLU. Against KLU on the same matrices, CHOLMOD factorises
/// 2.1–2.3× and solves 2.5–6× faster (1.3k, 5.6k and 14.6k dofs: 3.8 → 2.3 ms and
/// 0.15 → 0.06 ms, 125 → 70 ms and 4.0 → 0.6 ms, 658 → 286 ms and 13.3 → 8.9 ms).
#include <Eigen/Core>
#include <memory>
#include <vector>

#include "engine/dae_system.hpp"

namespace kelvin {

class SchurSolver {
 public:
  explicit SchurSolver(DaeSystem& dae);
  ~SchurSolver();
  SchurSolver(const SchurSolver&) = delete;
  SchurSolver& operator=(const SchurSolver&) = delete;

  /// Assembles S at (t, y) for c_j; false when an element is inadmissible.
  bool assemble(double t, double cj, const double* y);
  /// Forms S for c_j from the K and D the DaeSystem assembled last (the caller made
  /// sure they belong to the wanted state): saves an assembly when the residual
  /// already needed them.
  void assemble_from_last(double cj);
  /// Factorises the last assembled S; false when it is singular.
  bool factorize();
  /// True when the last factorisation fell back to KLU (S not positive definite).
  bool factored_by_lu() const { return lu_active_; }
  /// x = J⁻¹ b for the J of the last assemble()/factorize() (x may alias b).
  void solve(const double* b, double* x);
  /// x = J_B⁻¹ b for the Newton matrix of the adjoint problem,
  ///   J_B = [ c_B I   −Kᵀ   f_xᵀ ; I   c_B M − Dᵀ   0 ; 0   −K_xzᵀ   c_B I + f_zᵀ ],
  /// using the S of assemble(t, −c_B, y): x₂ solves Sᵀ x₂ = c_B r₂ − r₁ − f_xᵀA⁻ᵀ r₃,
  /// x₃ = −A⁻ᵀ(r₃ + K_xzᵀ x₂) and x₁ = (r₁ + Kᵀ x₂ − f_xᵀ x₃)/c_B — the transposed
  /// factorisation, no new pattern.
  void solve_adjoint(const double* b, double* x);
  double cj() const { return cj_; }

 private:
  struct Klu;
  struct Cholmod;
  /// x ← S⁻¹ x (transposed: S⁻ᵀ) with the current factorisation.
  void apply_inverse(double* x, bool transposed);
  DaeSystem& dae_;
  int n_;
  double cj_ = 0;
  std::vector<double> S_, S_sym_, K_, D_;  // values in the FEM pattern
  std::vector<int> transpose_;             // pattern index of entry (j, i) for entry (i, j)
  Eigen::VectorXd rhs_, r1_;
  /// Per internal block, at the last assembly: A⁻¹, K_xz and f_x.
  std::vector<Eigen::MatrixXd> A_inv_;
  std::vector<Eigen::Matrix<double, 12, Eigen::Dynamic>> Kxz_;
  std::vector<Eigen::Matrix<double, Eigen::Dynamic, 12>> fx_;
  std::vector<char> coupled_;  // InternalLinearisation::coupled
  /// One block's values in the eliminations (sized for the largest block) and the
  /// adjoint's f_xᵀ x₃, reused so that a solve does not allocate.
  Eigen::VectorXd block_, fx3_;
  std::vector<Eigen::VectorXd> z_;
  std::unique_ptr<Klu> klu_;
  std::unique_ptr<Cholmod> cholmod_;
  bool lu_active_ = false;
};

}  // namespace kelvin
