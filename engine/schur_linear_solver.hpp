#pragma once
/// \file
/// Internal to the IDAS wrappers (IdasIntegrator, IdasBackward): the one
/// SUNLinearSolver of kelvin, backed by a SchurSolver, and the one check of SUNDIALS
/// set-up calls.
#include <sundials/sundials_linearsolver.h>

#include "engine/idas_integrator.hpp"
#include "engine/schur_solver.hpp"

namespace kelvin {

/// What the adapter works on: setup factorises the matrix the Jacobian callback
/// assembled (singular: a recoverable failure, IDAS retries with a smaller step);
/// solve applies the forward Newton system, or with `adjoint` the backward one
/// (SchurSolver::solve_adjoint). Setup and solve times go to `stats` when given.
struct SchurLinearSolver {
  SchurSolver* schur = nullptr;
  bool adjoint = false;
  IntegratorStats* stats = nullptr;
};

/// A SUNLinearSolver whose content is `content` (which must outlive it); freed with
/// SUNLinSolFree.
SUNLinearSolver make_schur_linear_solver(SUNContext ctx, SchurLinearSolver* content);

/// Throws kelvin::Error naming the call when a SUNDIALS set-up call failed (flag < 0).
void check_sundials(int flag, const char* call);

/// IDAS's own counters of `mem` (residuals, Jacobians, setups, error-test and
/// convergence failures) into `stats`; steps are left to the caller.
void read_idas_counters(void* mem, IntegratorStats& stats);

}  // namespace kelvin
