#pragma once
/// \file
/// Direct solver for the IDAS Newton systems of the DAE (dae_system.hpp),
///   [ c_j I      −I       ] [a]   [r₁]
///   [ K      c_j M + D    ] [b] = [r₂],
/// by eliminating the velocity block: b = c_j a − r₁ and
///   S a = r₂ + (c_j M + D) r₁,   S = K + c_j D + c_j² M,
/// an n × n system with the FEM sparsity pattern, factorised by KLU (AMD ordering).
/// Half the unknowns and a fraction of the fill of factorising the 2n × 2n matrix:
/// bench_forward measures the difference.
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
  /// x = J⁻¹ b for the J of the last assemble()/factorize() (x may alias b).
  void solve(const double* b, double* x);
  /// x = J_B⁻¹ b for the Newton matrix of the adjoint problem,
  ///   J_B = [ c_B I   −Kᵀ ; I   c_B M − Dᵀ ],
  /// using the S of assemble(t, −c_B, y): b₂ solves Sᵀ x₂ = c_B r₂ − r₁ and
  /// x₁ = (r₁ + Kᵀ x₂)/c_B — the transposed factorisation, no new pattern.
  void solve_adjoint(const double* b, double* x);
  double cj() const { return cj_; }

 private:
  struct Klu;
  DaeSystem& dae_;
  int n_;
  double cj_ = 0;
  std::vector<double> S_, K_, D_;  // values in the FEM pattern
  Eigen::VectorXd rhs_, r1_;
  std::unique_ptr<Klu> klu_;
};

}  // namespace kelvin
