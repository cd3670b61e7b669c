#include "engine/schur_linear_solver.hpp"

#include <fmt/format.h>
#include <idas/idas.h>
#include <nvector/nvector_serial.h>

#include <chrono>

#include "base/error.hpp"

namespace kelvin {
namespace {

using Clock = std::chrono::steady_clock;

SchurLinearSolver* content_of(SUNLinearSolver S) {
  return static_cast<SchurLinearSolver*>(S->content);
}
SUNLinearSolver_Type schur_type(SUNLinearSolver) {
  return SUNLINEARSOLVER_DIRECT;
}
SUNLinearSolver_ID schur_id(SUNLinearSolver) {
  return SUNLINEARSOLVER_CUSTOM;
}
int schur_setup(SUNLinearSolver S, SUNMatrix) {
  SchurLinearSolver& c = *content_of(S);
  const auto start = Clock::now();
  const bool ok = c.schur->factorize();
  if (c.stats)
    c.stats->setup_seconds += std::chrono::duration<double>(Clock::now() - start).count();
  return ok ? 0 : SUNLS_PACKAGE_FAIL_REC;
}
int schur_solve(SUNLinearSolver S, SUNMatrix, N_Vector x, N_Vector b, realtype) {
  SchurLinearSolver& c = *content_of(S);
  const auto start = Clock::now();
  if (c.adjoint)
    c.schur->solve_adjoint(N_VGetArrayPointer(b), N_VGetArrayPointer(x));
  else
    c.schur->solve(N_VGetArrayPointer(b), N_VGetArrayPointer(x));
  if (c.stats) {
    c.stats->solve_seconds += std::chrono::duration<double>(Clock::now() - start).count();
    ++c.stats->linear_solves;
  }
  return 0;
}
int schur_free(SUNLinearSolver S) {
  SUNLinSolFreeEmpty(S);
  return 0;
}

}  // namespace

SUNLinearSolver make_schur_linear_solver(SUNContext ctx, SchurLinearSolver* content) {
  SUNLinearSolver S = SUNLinSolNewEmpty(ctx);
  if (!S) return nullptr;
  S->content = content;
  S->ops->gettype = schur_type;
  S->ops->getid = schur_id;
  S->ops->setup = schur_setup;
  S->ops->solve = schur_solve;
  S->ops->free = schur_free;
  return S;
}

void read_idas_counters(void* mem, IntegratorStats& s) {
  long v = 0;
  if (IDAGetNumResEvals(mem, &v) == 0) s.residual_evals = v;
  if (IDAGetNumJacEvals(mem, &v) == 0) s.jacobian_evals = v;
  if (IDAGetNumLinSolvSetups(mem, &v) == 0) s.linear_setups = v;
  if (IDAGetNumErrTestFails(mem, &v) == 0) s.error_test_failures = v;
  if (IDAGetNumNonlinSolvConvFails(mem, &v) == 0) s.convergence_failures = v;
}

void check_sundials(int flag, const char* call) {
  if (flag < 0) throw Error(fmt::format("IDAS setup failed in {} (flag {})", call, flag));
}

}  // namespace kelvin
