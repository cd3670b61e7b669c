#include "engine/idas_backward.hpp"

#include <fmt/format.h>
#include <idas/idas.h>
#include <nvector/nvector_serial.h>
#include <sunmatrix/sunmatrix_sparse.h>

#include "base/error.hpp"
#include "engine/schur_linear_solver.hpp"
#include "engine/state_vector.hpp"

namespace kelvin {

struct IdasBackward::Impl {
  BackwardProblem problem;
  SchurLinearSolver linear_solver;
  void* mem = nullptr;  // the forward integrator's
  int which = 0;
  double t1 = 0;
  N_Vector l = nullptr, lp = nullptr, q = nullptr, atol = nullptr;
  N_Vector l0 = nullptr, lp0 = nullptr;  // the initial values every solve restarts from
  SUNMatrix J = nullptr;
  SUNLinearSolver LS = nullptr;
  bool solved = false;
  std::string fatal;  // an exception's message from a callback

  ~Impl() {
    for (N_Vector v : {l, lp, q, atol, l0, lp0})
      if (v) N_VDestroy(v);
    if (LS) SUNLinSolFree(LS);
    if (J) SUNMatDestroy(J);
  }

  /// Exceptions must not cross IDAS's C frames: they end the solve, message kept.
  template <class Body>
  int guarded(Body body) {
    try {
      return body() ? 0 : 1;
    } catch (const std::exception& e) {
      fatal = e.what();
      return -1;
    }
  }
};

namespace {

IdasBackward::Impl* impl_of(void* data) {
  return static_cast<IdasBackward::Impl*>(data);
}

int residual_fn(realtype t, N_Vector y, N_Vector, N_Vector l, N_Vector lp, N_Vector r, void* data) {
  auto* m = impl_of(data);
  return m->guarded([&] {
    return m->problem.residual(t, N_VGetArrayPointer(y), N_VGetArrayPointer(l),
                               N_VGetArrayPointer(lp), N_VGetArrayPointer(r));
  });
}

int quadrature_fn(realtype t, N_Vector y, N_Vector yp, N_Vector l, N_Vector, N_Vector q,
                  void* data) {
  auto* m = impl_of(data);
  return m->guarded([&] {
    return m->problem.quadrature(t, N_VGetArrayPointer(y), N_VGetArrayPointer(yp),
                                 N_VGetArrayPointer(l), N_VGetArrayPointer(q));
  });
}

int jacobian_fn(realtype t, realtype cj, N_Vector y, N_Vector, N_Vector, N_Vector, N_Vector,
                SUNMatrix, void* data, N_Vector, N_Vector, N_Vector) {
  auto* m = impl_of(data);
  return m->guarded([&] { return m->problem.jacobian(t, cj, N_VGetArrayPointer(y)); });
}

}  // namespace

IdasBackward::IdasBackward(IdasIntegrator& forward, BackwardProblem problem, double t1,
                           const Eigen::VectorXd& lambda, const Eigen::VectorXd& lambda_rate,
                           int nq, int max_order, long max_steps)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.problem = std::move(problem);
  m.linear_solver = {m.problem.schur, true, nullptr};
  m.mem = forward.idas_memory();
  m.t1 = t1;
  auto ctx = static_cast<SUNContext>(forward.sundials_context());
  const auto size = static_cast<int>(lambda.size());
  m.l = new_state_vector(size, ctx);
  m.lp = new_state_vector(size, ctx);
  m.l0 = new_state_vector(size, ctx);
  m.lp0 = new_state_vector(size, ctx);
  m.atol = new_state_vector(size, ctx);
  m.q = N_VNew_Serial(nq, ctx);
  Eigen::Map<Eigen::VectorXd>(N_VGetArrayPointer(m.l0), size) = lambda;
  Eigen::Map<Eigen::VectorXd>(N_VGetArrayPointer(m.lp0), size) = lambda_rate;
  N_VScale(1.0, m.l0, m.l);
  N_VScale(1.0, m.lp0, m.lp);
  N_VConst(0.0, m.q);
  // The Newton matrix lives in the SchurSolver; IDAS only needs a placeholder.
  m.J = SUNSparseMatrix(size, size, 1, CSC_MAT, ctx);
  m.LS = make_schur_linear_solver(ctx, &m.linear_solver);
  if (!m.J || !m.LS) throw Error("could not create the adjoint's linear solver");

  check_sundials(IDACreateB(m.mem, &m.which), "IDACreateB");
  check_sundials(IDAInitB(m.mem, m.which, residual_fn, t1, m.l, m.lp), "IDAInitB");
  check_sundials(IDASetUserDataB(m.mem, m.which, &m), "IDASetUserDataB");
  check_sundials(IDASetMaxNumStepsB(m.mem, m.which, max_steps), "IDASetMaxNumStepsB");
  check_sundials(IDASetMaxOrdB(m.mem, m.which, max_order), "IDASetMaxOrdB");
  check_sundials(IDASetLinearSolverB(m.mem, m.which, m.LS, m.J), "IDASetLinearSolverB");
  check_sundials(IDASetJacFnB(m.mem, m.which, jacobian_fn), "IDASetJacFnB");
  check_sundials(IDAQuadInitB(m.mem, m.which, quadrature_fn, m.q), "IDAQuadInitB");
  check_sundials(IDASetQuadErrConB(m.mem, m.which, SUNFALSE), "IDASetQuadErrConB");
}

IdasBackward::~IdasBackward() = default;

bool IdasBackward::solve(double t0, double rtol, const Eigen::VectorXd& atol) {
  Impl& m = *impl_;
  if (m.solved) {
    N_VScale(1.0, m.l0, m.l);
    N_VScale(1.0, m.lp0, m.lp);
    N_VConst(0.0, m.q);
    check_sundials(IDAReInitB(m.mem, m.which, m.t1, m.l, m.lp), "IDAReInitB");
    check_sundials(IDAQuadReInitB(m.mem, m.which, m.q), "IDAQuadReInitB");
  }
  m.solved = true;
  Eigen::Map<Eigen::VectorXd>(N_VGetArrayPointer(m.atol), atol.size()) = atol;
  check_sundials(IDASVtolerancesB(m.mem, m.which, rtol, m.atol), "IDASVtolerancesB");
  m.fatal.clear();
  error_.clear();
  const int flag = IDASolveB(m.mem, t0, IDA_NORMAL);
  if (flag < 0) {
    error_ = fmt::format("{}{}", IDAGetReturnFlagName(flag), m.fatal.empty() ? "" : ": " + m.fatal);
    return false;
  }
  double t = 0;
  check_sundials(IDAGetB(m.mem, m.which, &t, m.l, m.lp), "IDAGetB");
  check_sundials(IDAGetQuadB(m.mem, m.which, &t, m.q), "IDAGetQuadB");
  return true;
}

Eigen::VectorXd IdasBackward::lambda() const {
  return Eigen::Map<const Eigen::VectorXd>(N_VGetArrayPointer(impl_->l), N_VGetLength(impl_->l));
}

Eigen::VectorXd IdasBackward::quadrature() const {
  return Eigen::Map<const Eigen::VectorXd>(N_VGetArrayPointer(impl_->q), N_VGetLength(impl_->q));
}

IntegratorStats IdasBackward::stats() const {
  IntegratorStats s;
  void* mem_b = IDAGetAdjIDABmem(impl_->mem, impl_->which);
  long v = 0;
  if (IDAGetNumSteps(mem_b, &v) == 0) s.steps = v;
  read_idas_counters(mem_b, s);
  return s;
}

}  // namespace kelvin
