#pragma once
/// \file
/// A backward (adjoint) problem solved by IDAS over the steps a forward
/// IdasIntegrator stored (record_checkpoints): the adjoint's physics comes in as
/// callbacks at the forward states IDAS asks for; IDAS's memory, vectors, linear
/// solver and error handling stay here, in the engine.
#include <Eigen/Core>
#include <functional>
#include <memory>
#include <string>

#include "engine/idas_integrator.hpp"
#include "engine/schur_solver.hpp"

namespace kelvin {

struct BackwardProblem {
  /// The backward residual at the forward state y (2n entries) for (λ, λ').
  std::function<bool(double t, const double* y, const double* l, const double* lp, double* r)>
      residual;
  /// The quadrature integrands at the forward state (y, y') for λ (nq entries).
  std::function<bool(double t, const double* y, const double* yp, const double* l, double* q)>
      quadrature;
  /// Assembles the Newton matrix for c_j at the forward state into `schur`, whose
  /// solve_adjoint then solves the Newton systems.
  std::function<bool(double t, double cj, const double* y)> jacobian;
  SchurSolver* schur = nullptr;
};

/// Callbacks return false for an inadmissible state (IDAS retries with a smaller
/// step); an exception ends the solve with its message in error().
class IdasBackward {
 public:
  /// Starts at t1 from (λ, λ') with nq quadratures at 0; the forward integrator
  /// must have recorded its steps and reached t1.
  IdasBackward(IdasIntegrator& forward, BackwardProblem problem, double t1,
               const Eigen::VectorXd& lambda, const Eigen::VectorXd& lambda_rate, int nq,
               int max_order, long max_steps);
  ~IdasBackward();
  IdasBackward(const IdasBackward&) = delete;
  IdasBackward& operator=(const IdasBackward&) = delete;

  /// Integrates back to t0 with relative tolerance rtol and absolute tolerances
  /// atol (2n), each call from the initial values again. False on failure, with
  /// error() naming IDAS's flag and the callback's message.
  bool solve(double t0, double rtol, const Eigen::VectorXd& atol);
  /// λ and the quadratures at t0 after a successful solve.
  Eigen::VectorXd lambda() const;
  Eigen::VectorXd quadrature() const;
  /// IDAS's counters of the last solve.
  IntegratorStats stats() const;
  const std::string& error() const { return error_; }

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
  std::string error_;
};

}  // namespace kelvin
