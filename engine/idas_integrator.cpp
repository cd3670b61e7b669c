#include "engine/idas_integrator.hpp"

#include <fmt/format.h>
#include <idas/idas.h>
#include <nvector/nvector_serial.h>
#include <sunmatrix/sunmatrix_sparse.h>

#include <chrono>
#include <cmath>
#include <vector>

#include "base/error.hpp"
#include "engine/dae_system.hpp"
#include "engine/schur_linear_solver.hpp"
#include "engine/schur_solver.hpp"
#include "engine/state_vector.hpp"

namespace kelvin {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

}  // namespace

struct IdasIntegrator::Impl {
  const FemModel& model;
  IntegratorOptions opt;
  int n = 0;
  int size = 0;  // of the state: 2n + the internal variables
  SUNContext ctx = nullptr;
  void* mem = nullptr;
  N_Vector y = nullptr, yp = nullptr, yout = nullptr, atol = nullptr;
  Eigen::VectorXd rest;            // rest positions of the free dofs (the error weights' origin)
  Eigen::VectorXd internal_share;  // FemModel::internal_error_share
  SUNMatrix J = nullptr;
  SUNLinearSolver LS = nullptr;
  double t_solver = 0;  // internal time of IDAS
  bool checkpointing = false;
  bool order_set = false;  // IDASetMaxOrd is called by the first advance_to

  // optional quadratures and forward sensitivities
  QuadratureRhs quad_rhs;
  N_Vector q = nullptr;
  bool quad_error_control = false;
  SensitivityResidual sens_res;
  QuadratureSensitivityRhs quad_sens_rhs;
  int ns = 0;
  N_Vector *yS = nullptr, *ypS = nullptr, *qS = nullptr;

  DaeSystem dae;
  SchurSolver schur{dae};
  SchurLinearSolver linear_solver{&schur, false, &stats};

  // diagnostics
  IntegratorStats stats;
  std::string last_idas_message;
  std::string fatal_message;  // from an exception inside a callback
  int failed_element = -1;
  double failed_det = 0, failed_time = 0;

  Impl(const FemModel& m, const IntegratorOptions& o)
      : model(m), opt(o), n(m.num_dofs()), size(2 * n + m.num_internal()), dae(m) {}

  ~Impl() {
    if (mem) IDAFree(&mem);
    if (LS) SUNLinSolFreeEmpty(LS);
    if (J) SUNMatDestroy(J);
    for (N_Vector v : {y, yp, yout, atol, q})
      if (v) N_VDestroy(v);
    for (N_Vector* a : {yS, ypS, qS})
      if (a) N_VDestroyVectorArray(a, ns);
    if (ctx) SUNContext_Free(&ctx);
  }

  void record_failure(double t) {
    failed_element = dae.last_assembly().failed_element;
    failed_det = dae.last_assembly().failed_det;
    failed_time = t;
  }

  /// Runs a callback body: inadmissible states are recoverable (IDAS retries with
  /// a smaller step); exceptions (e.g. a plugin that failed) must not cross the C
  /// frames of IDAS, so they become an unrecoverable failure with their message kept.
  template <class Body>
  int guarded(double t, double& seconds, Body body) {
    if (opt.interrupt && opt.interrupt->load()) {
      fatal_message = "interrupted";
      return -1;
    }
    const auto start = Clock::now();
    bool ok = false;
    try {
      ok = body();
    } catch (const std::exception& e) {
      fatal_message = e.what();
      return -1;
    }
    seconds += seconds_since(start);
    if (!ok) record_failure(t);
    return ok ? 0 : 1;
  }

  int residual(double t, const double* y, const double* yp, double* r) {
    return guarded(t, stats.residual_seconds, [&] { return dae.residual(t, y, yp, r); });
  }

  /// Wraps a client callback (quadrature or sensitivity): same failure rules as
  /// the residual.
  template <class Body>
  int client(double t, Body body) {
    double unused = 0;
    return guarded(t, unused, body);
  }

  int jacobian(double t, double cj, const double* y) {
    return guarded(t, stats.jacobian_seconds, [&] { return schur.assemble(t, cj, y); });
  }
};

namespace {

int residual_fn(realtype t, N_Vector y, N_Vector yp, N_Vector r, void* data) {
  auto* impl = static_cast<IdasIntegrator::Impl*>(data);
  return impl->residual(t, N_VGetArrayPointer(y), N_VGetArrayPointer(yp), N_VGetArrayPointer(r));
}

int jacobian_fn(realtype t, realtype cj, N_Vector y, N_Vector, N_Vector, SUNMatrix, void* data,
                N_Vector, N_Vector, N_Vector) {
  auto* impl = static_cast<IdasIntegrator::Impl*>(data);
  return impl->jacobian(t, cj, N_VGetArrayPointer(y));
}

/// IDAS's error weights 1/(rtol·|y| + atol) with positions measured from the rest
/// shape, not from the coordinate origin: a body meshed 1 m from the origin would
/// otherwise get a 1000× looser position tolerance than one meshed at it (0.1 mm at
/// rtol 1e-4, more than a marker's whole misfit). On the bench bar at rtol 1e-3
/// this also cut the integration error in the marker RMS by a quarter at the same
/// number of steps.
int error_weights(N_Vector y, N_Vector weights, void* data) {
  const auto& m = *static_cast<const IdasIntegrator::Impl*>(data);
  const double* yy = N_VGetArrayPointer(y);
  const double* atol = N_VGetArrayPointer(m.atol);
  double* w = N_VGetArrayPointer(weights);
  for (int i = 0; i < m.n; ++i) w[i] = 1.0 / (m.opt.rtol * std::abs(yy[i] - m.rest[i]) + atol[i]);
  for (int i = m.n; i < 2 * m.n; ++i) w[i] = 1.0 / (m.opt.rtol * std::abs(yy[i]) + atol[i]);
  for (int i = 2 * m.n; i < m.size; ++i)
    w[i] = m.internal_share[i - 2 * m.n] / (m.opt.rtol * std::abs(yy[i]) + atol[i]);
  return 0;
}

int quadrature_fn(realtype t, N_Vector y, N_Vector yp, N_Vector q, void* data) {
  auto* impl = static_cast<IdasIntegrator::Impl*>(data);
  return impl->client(t, [&] {
    return impl->quad_rhs(t, N_VGetArrayPointer(y), N_VGetArrayPointer(yp), N_VGetArrayPointer(q));
  });
}

std::vector<double*> pointers(int n, N_Vector* v) {
  std::vector<double*> p(n);
  for (int i = 0; i < n; ++i) p[i] = N_VGetArrayPointer(v[i]);
  return p;
}

int sensitivity_fn(int ns, realtype t, N_Vector y, N_Vector yp, N_Vector, N_Vector* yS,
                   N_Vector* ypS, N_Vector* resS, void* data, N_Vector, N_Vector, N_Vector) {
  auto* impl = static_cast<IdasIntegrator::Impl*>(data);
  const auto s = pointers(ns, yS), sp = pointers(ns, ypS), r = pointers(ns, resS);
  return impl->client(t, [&] {
    return impl->sens_res(t, N_VGetArrayPointer(y), N_VGetArrayPointer(yp), ns, s.data(), sp.data(),
                          r.data());
  });
}

int quadrature_sensitivity_fn(int ns, realtype t, N_Vector y, N_Vector yp, N_Vector* yS, N_Vector*,
                              N_Vector, N_Vector* qS, void* data, N_Vector, N_Vector, N_Vector) {
  auto* impl = static_cast<IdasIntegrator::Impl*>(data);
  const auto s = pointers(ns, yS), q = pointers(ns, qS);
  return impl->client(t, [&] {
    return impl->quad_sens_rhs(t, N_VGetArrayPointer(y), N_VGetArrayPointer(yp), ns, s.data(),
                               q.data());
  });
}

void error_handler(int, const char* module, const char* function, char* msg, void* data) {
  auto* impl = static_cast<IdasIntegrator::Impl*>(data);
  impl->last_idas_message = fmt::format("{} {}: {}", module, function, msg);
}

}  // namespace

double IntegratorStats::mean_order() const {
  long total = 0, weighted = 0;
  for (int q = 1; q <= 5; ++q) {
    total += order_histogram[q];
    weighted += q * order_histogram[q];
  }
  return total ? static_cast<double>(weighted) / total : 0.0;
}

IntegratorStats& IntegratorStats::operator+=(const IntegratorStats& o) {
  steps += o.steps;
  residual_evals += o.residual_evals;
  jacobian_evals += o.jacobian_evals;
  linear_setups += o.linear_setups;
  linear_solves += o.linear_solves;
  error_test_failures += o.error_test_failures;
  convergence_failures += o.convergence_failures;
  for (size_t q = 0; q < order_histogram.size(); ++q) order_histogram[q] += o.order_histogram[q];
  jacobian_seconds += o.jacobian_seconds;
  setup_seconds += o.setup_seconds;
  solve_seconds += o.solve_seconds;
  residual_seconds += o.residual_seconds;
  return *this;
}

IdasIntegrator::IdasIntegrator(const FemModel& model, const IntegratorOptions& options)
    : impl_(std::make_unique<Impl>(model, options)) {}

IdasIntegrator::~IdasIntegrator() = default;

void IdasIntegrator::initialize(double t0, const Eigen::VectorXd& x0, const Eigen::VectorXd& v0,
                                const Eigen::VectorXd& z0) {
  Impl& m = *impl_;
  const int n = m.n, nz = m.size - 2 * n;
  if (n == 0) throw Error("every node is clamped: there is nothing to simulate");
  check_sundials(SUNContext_Create(nullptr, &m.ctx), "SUNContext_Create");
  m.y = new_state_vector(m.size, m.ctx, nz > 0);
  m.yp = new_state_vector(m.size, m.ctx, nz > 0);
  m.yout = new_state_vector(m.size, m.ctx, nz > 0);
  m.atol = new_state_vector(m.size, m.ctx, nz > 0);
  double* y = N_VGetArrayPointer(m.y);
  double* yp = N_VGetArrayPointer(m.yp);
  Eigen::Map<Eigen::VectorXd>(y, n) = x0;
  Eigen::Map<Eigen::VectorXd>(y + n, n) = v0;
  if (nz > 0) {
    if (z0.size() == nz) {
      Eigen::Map<Eigen::VectorXd>(y + 2 * n, nz) = z0;
    } else {
      Eigen::Matrix3Xd x, v;
      m.model.expand(t0, x0.data(), nullptr, x, v);
      m.model.relaxed_internal(x, y + 2 * n);
    }
  }

  if (!m.dae.consistent_derivative(t0, y, yp))
    throw Error(fmt::format("initial state: element {} is inverted (det F = {:.3g})",
                            m.dae.last_assembly().failed_element,
                            m.dae.last_assembly().failed_det));

  m.mem = IDACreate(m.ctx);
  if (!m.mem) throw Error("IDACreate failed");
  check_sundials(IDASetErrHandlerFn(m.mem, error_handler, &m), "IDASetErrHandlerFn");
  check_sundials(IDAInit(m.mem, residual_fn, t0, m.y, m.yp), "IDAInit");
  double* atol = N_VGetArrayPointer(m.atol);
  for (int i = 0; i < n; ++i) {
    atol[i] = m.opt.atol;
    atol[n + i] = m.opt.atol * m.opt.velocity_atol_scale;
  }
  // Internal variables are strains: the position tolerance over the body's size.
  const double extent =
      (m.model.mesh().nodes.rowwise().maxCoeff() - m.model.mesh().nodes.rowwise().minCoeff())
          .maxCoeff();
  for (int i = 2 * n; i < m.size; ++i) atol[i] = m.opt.atol / std::max(extent, 1e-300);
  m.internal_share = m.model.internal_error_share();
  m.rest.resize(n);
  m.model.restrict(m.model.mesh().nodes, m.rest.data());
  check_sundials(IDASetUserData(m.mem, &m), "IDASetUserData");  // before IDAWFtolerances: its data
  check_sundials(IDAWFtolerances(m.mem, error_weights), "IDAWFtolerances");
  // The Newton matrix lives in SchurSolver; IDAS only needs a placeholder matrix.
  m.J = SUNSparseMatrix(m.size, m.size, 1, CSC_MAT, m.ctx);
  m.LS = make_schur_linear_solver(m.ctx, &m.linear_solver);
  if (!m.J || !m.LS) throw Error("could not create the IDAS linear solver");
  check_sundials(IDASetLinearSolver(m.mem, m.LS, m.J), "IDASetLinearSolver");
  check_sundials(IDASetJacFn(m.mem, jacobian_fn), "IDASetJacFn");
  check_sundials(IDASetMaxNumSteps(m.mem, m.opt.max_steps), "IDASetMaxNumSteps");
  if (m.opt.max_step > 0) check_sundials(IDASetMaxStep(m.mem, m.opt.max_step), "IDASetMaxStep");
  if (m.opt.initial_step > 0)
    check_sundials(IDASetInitStep(m.mem, m.opt.initial_step), "IDASetInitStep");
  m.t_solver = t0;
  t_ = t0;
  x_ = x0;
  v_ = v0;
  z_ = Eigen::Map<const Eigen::VectorXd>(y + 2 * n, nz);
}

void IdasIntegrator::add_quadrature(int nq, QuadratureRhs rhs, bool error_control, double atol) {
  Impl& m = *impl_;
  m.quad_rhs = std::move(rhs);
  m.q = N_VNew_Serial(nq, m.ctx);
  N_VConst(0.0, m.q);
  check_sundials(IDAQuadInit(m.mem, quadrature_fn, m.q), "IDAQuadInit");
  m.quad_error_control = error_control;
  if (error_control) {
    check_sundials(IDAQuadSStolerances(m.mem, m.opt.rtol, atol), "IDAQuadSStolerances");
    check_sundials(IDASetQuadErrCon(m.mem, SUNTRUE), "IDASetQuadErrCon");
  }
}

Eigen::VectorXd IdasIntegrator::quadrature() const {
  const Impl& m = *impl_;
  if (IDAGetQuadDky(m.mem, t_, 0, m.q) < 0)
    throw Error(fmt::format("could not interpolate the quadratures at t = {:.6g} s", t_));
  return Eigen::Map<const Eigen::VectorXd>(N_VGetArrayPointer(m.q), N_VGetLength(m.q));
}

void IdasIntegrator::add_sensitivities(SensitivityResidual res, const Eigen::MatrixXd& yS0,
                                       const Eigen::MatrixXd& ypS0, const Eigen::VectorXd& pbar,
                                       bool error_control) {
  Impl& m = *impl_;
  m.sens_res = std::move(res);
  m.ns = static_cast<int>(yS0.cols());
  m.yS = N_VCloneVectorArray(m.ns, m.y);
  m.ypS = N_VCloneVectorArray(m.ns, m.y);
  for (int i = 0; i < m.ns; ++i) {
    Eigen::Map<Eigen::VectorXd>(N_VGetArrayPointer(m.yS[i]), m.size) = yS0.col(i);
    Eigen::Map<Eigen::VectorXd>(N_VGetArrayPointer(m.ypS[i]), m.size) = ypS0.col(i);
  }
  check_sundials(IDASensInit(m.mem, m.ns, IDA_STAGGERED, sensitivity_fn, m.yS, m.ypS),
                 "IDASensInit");
  std::vector<double> bar(pbar.data(), pbar.data() + pbar.size());
  check_sundials(IDASetSensParams(m.mem, nullptr, bar.data(), nullptr), "IDASetSensParams");
  // IDAS's estimated tolerances (IDASensEEtolerances) would pass pbar·sᵢ through
  // error_weights, which measures positions from the rest shape. These are the same
  // weights, pbar/(rtol·pbar|s| + atol), without that origin: sensitivities are
  // derivatives of displacements already.
  N_Vector* atol_s = N_VCloneVectorArray(m.ns, m.atol);
  for (int i = 0; i < m.ns; ++i) N_VScale(1.0 / pbar[i], m.atol, atol_s[i]);
  const int flag = IDASensSVtolerances(m.mem, m.opt.rtol, atol_s);
  N_VDestroyVectorArray(atol_s, m.ns);
  check_sundials(flag, "IDASensSVtolerances");
  check_sundials(IDASetSensErrCon(m.mem, error_control ? SUNTRUE : SUNFALSE), "IDASetSensErrCon");
}

Eigen::MatrixXd IdasIntegrator::state_sensitivities() const {
  const Impl& m = *impl_;
  Eigen::MatrixXd out(m.size, m.ns);
  if (m.ns == 0) return out;
  N_Vector* s = N_VCloneVectorArray(m.ns, m.y);
  const int flag = IDAGetSensDky(m.mem, t_, 0, s);
  for (int i = 0; i < m.ns; ++i)
    out.col(i) = Eigen::Map<const Eigen::VectorXd>(N_VGetArrayPointer(s[i]), m.size);
  N_VDestroyVectorArray(s, m.ns);
  if (flag < 0)
    throw Error(fmt::format("could not interpolate the sensitivities at t = {:.6g} s", t_));
  return out;
}

void IdasIntegrator::add_quadrature_sensitivities(QuadratureSensitivityRhs rhs) {
  Impl& m = *impl_;
  m.quad_sens_rhs = std::move(rhs);
  m.qS = N_VCloneVectorArray(m.ns, m.q);
  for (int i = 0; i < m.ns; ++i) N_VConst(0.0, m.qS[i]);
  check_sundials(IDAQuadSensInit(m.mem, quadrature_sensitivity_fn, m.qS), "IDAQuadSensInit");
  if (m.quad_error_control) {
    check_sundials(IDAQuadSensEEtolerances(m.mem), "IDAQuadSensEEtolerances");
    check_sundials(IDASetQuadSensErrCon(m.mem, SUNTRUE), "IDASetQuadSensErrCon");
  }
}

Eigen::MatrixXd IdasIntegrator::quadrature_sensitivities() const {
  const Impl& m = *impl_;
  if (IDAGetQuadSensDky(m.mem, t_, 0, m.qS) < 0)
    throw Error(
        fmt::format("could not interpolate the quadrature sensitivities at t = {:.6g} s", t_));
  const int nq = static_cast<int>(N_VGetLength(m.q));
  Eigen::MatrixXd out(nq, m.ns);
  for (int i = 0; i < m.ns; ++i)
    out.col(i) = Eigen::Map<const Eigen::VectorXd>(N_VGetArrayPointer(m.qS[i]), nq);
  return out;
}

void IdasIntegrator::record_checkpoints(long steps) {
  check_sundials(IDAAdjInit(impl_->mem, steps, IDA_HERMITE), "IDAAdjInit");
  impl_->checkpointing = true;
}

void* IdasIntegrator::idas_memory() const {
  return impl_->mem;
}

void* IdasIntegrator::sundials_context() const {
  return impl_->ctx;
}

double IdasIntegrator::solver_time() const {
  return impl_->t_solver;
}

bool IdasIntegrator::advance_to(double tout, double t_stop, long step_budget) {
  Impl& m = *impl_;
  const int n = m.n;
  check_sundials(IDASetStopTime(m.mem, t_stop), "IDASetStopTime");
  if (!m.order_set) {
    // Not before the quadratures are added: IDAQuadInit sizes its history to the
    // maximum order at that call, and IDAS 6's adjoint checkpoints copy kk + 2
    // quadrature history vectors whatever it is (past the end below order 4).
    check_sundials(IDASetMaxOrd(m.mem, m.opt.max_order), "IDASetMaxOrd");
    m.order_set = true;
  }
  error_.clear();
  // One step at a time, so that the order of every step can be counted.
  while (m.t_solver < tout) {
    if (step_budget > 0 && m.stats.steps >= step_budget) return false;
    if (m.opt.interrupt && m.opt.interrupt->load()) {
      error_ = fmt::format("interrupted at t = {:.6g} s", m.t_solver);
      return false;
    }
    if (m.stats.steps >= m.opt.max_steps) {
      // Most often the steps shrank because some element is collapsing: say which.
      IDAGetDky(m.mem, m.t_solver, 0, m.yout);
      Eigen::Matrix3Xd x, v;
      m.model.expand(m.t_solver, N_VGetArrayPointer(m.yout), nullptr, x, v);
      const auto [element, det] = m.model.most_compressed_element(x);
      error_ = fmt::format(
          "stopped at t = {:.6g} s: the step limit solver.max_steps = {} was reached (the most "
          "compressed element is {}, det F = {:.3g})",
          m.t_solver, m.opt.max_steps, element, det);
      return false;
    }
    m.failed_element = -1;
    double tret = 0;
    int ncheck = 0;
    const int flag = m.checkpointing
                         ? IDASolveF(m.mem, t_stop, &tret, m.yout, m.yp, IDA_ONE_STEP, &ncheck)
                         : IDASolve(m.mem, t_stop, &tret, m.yout, m.yp, IDA_ONE_STEP);
    if (flag < 0) {
      double tcur = m.t_solver;
      IDAGetCurrentTime(m.mem, &tcur);
      std::string why = IDAGetReturnFlagName(flag);
      if (!m.fatal_message.empty())
        why += ": " + m.fatal_message;
      else if (m.failed_element >= 0)
        why +=
            fmt::format(": element {} is inverted or degenerate (det F = {:.3g}) at t = {:.6g} s",
                        m.failed_element, m.failed_det, m.failed_time);
      else if (!m.last_idas_message.empty())
        why += ": " + m.last_idas_message;
      error_ = fmt::format("the solver failed at t = {:.6g} s ({})", tcur, why);
      return false;
    }
    m.t_solver = tret;
    ++m.stats.steps;
    int order = 0;
    IDAGetLastOrder(m.mem, &order);
    if (order >= 1 && order <= 5) ++m.stats.order_histogram[order];
  }
  const double t = std::min(tout, m.t_solver);
  if (IDAGetDky(m.mem, t, 0, m.yout) < 0) {
    error_ = fmt::format("could not interpolate the state at t = {:.6g} s", t);
    return false;
  }
  const double* yo = N_VGetArrayPointer(m.yout);
  t_ = t;
  x_ = Eigen::Map<const Eigen::VectorXd>(yo, n);
  v_ = Eigen::Map<const Eigen::VectorXd>(yo + n, n);
  z_ = Eigen::Map<const Eigen::VectorXd>(yo + 2 * n, m.size - 2 * n);
  return true;
}

double IdasIntegrator::restart_step() const {
  const Impl& m = *impl_;
  int order = 0;
  if (!m.mem || IDAGetLastOrder(m.mem, &order) != IDA_SUCCESS || order < 2) return 0;
  N_Vector ydd = N_VClone(m.y), w = N_VClone(m.y);
  double h = 0;
  if (IDAGetDky(m.mem, t_, 2, ydd) == IDA_SUCCESS && IDAGetErrWeights(m.mem, w) == IDA_SUCCESS) {
    const double norm = N_VWrmsNorm(ydd, w);
    constexpr double kErrorShare = 0.25;  // of the tolerance, for the first step's ½h²‖ÿ‖
    if (norm > 0 && std::isfinite(norm)) h = std::sqrt(2 * kErrorShare / norm);
  }
  N_VDestroy(ydd);
  N_VDestroy(w);
  return h;
}

IntegratorStats IdasIntegrator::stats() const {
  IntegratorStats s = impl_->stats;
  void* mem = impl_->mem;
  if (mem) read_idas_counters(mem, s);
  return s;
}

}  // namespace kelvin
