#pragma once
/// \file
/// IDAS on the implicit first-order form of the equations of motion, y = (x, v, z)
/// (engine/dae_system.hpp), its Newton systems solved by SchurSolver.
#include <Eigen/Core>
#include <array>
#include <atomic>
#include <functional>
#include <memory>
#include <string>

#include "engine/fem_model.hpp"

namespace kelvin {

struct IntegratorOptions {
  double rtol = 1e-6;
  double atol = 1e-9;                // positions (m)
  double velocity_atol_scale = 100;  // velocities use atol × this (m/s)
  int max_order = 5;                 // 1 … 5 (choose_max_order picks one for `auto`)
  long max_steps = 1000000;
  double max_step = 0;      // 0 = unlimited
  double initial_step = 0;  // 0 = IDAS's choice
  /// Checked before every step and in every residual evaluation: a run caught in
  /// one long step (a blow-up, Newton failing at ever smaller steps) still stops.
  /// Not for runs with adjoint checkpoints (IDAS cannot free an adjoint memory whose
  /// first step failed).
  const std::atomic<bool>* interrupt = nullptr;
};

struct IntegratorStats {
  long steps = 0, residual_evals = 0, jacobian_evals = 0, linear_setups = 0, linear_solves = 0,
       error_test_failures = 0, convergence_failures = 0;
  std::array<long, 6> order_histogram{};  // steps taken at order 1..5 (index = order)
  double jacobian_seconds = 0, setup_seconds = 0, solve_seconds = 0, residual_seconds = 0;
  double mean_order() const;
  /// Adds another run's counters and times (passes of one evaluation).
  IntegratorStats& operator+=(const IntegratorStats& o);
};

/// Integrand of quadratures ∫ q(t, y) dt carried along the forward solve.
using QuadratureRhs = std::function<bool(double t, const double* y, const double* yp, double* q)>;
/// Forward-sensitivity residuals F_y sᵢ + F_y' sᵢ' + F_pᵢ for i < ns.
using SensitivityResidual =
    std::function<bool(double t, const double* y, const double* yp, int ns, const double* const* yS,
                       const double* const* ypS, double* const* resS)>;
/// Sensitivities of the quadrature integrand: ∂q/∂y sᵢ (+ ∂q/∂pᵢ).
using QuadratureSensitivityRhs =
    std::function<bool(double t, const double* y, const double* yp, int ns, const double* const* yS,
                       double* const* qS)>;

class IdasIntegrator {
 public:
  IdasIntegrator(const FemModel& model, const IntegratorOptions& options);
  ~IdasIntegrator();
  IdasIntegrator(const IdasIntegrator&) = delete;
  IdasIntegrator& operator=(const IdasIntegrator&) = delete;

  /// Starts at t0 from free-dof positions and velocities and the internal variables
  /// z0 (FemModel::num_internal of them; empty: relaxed at x0, as a body starts at
  /// rest or in equilibrium); computes a consistent y' from the equations of motion.
  /// Throws kelvin::Error when the initial state is inadmissible.
  void initialize(double t0, const Eigen::VectorXd& x0, const Eigen::VectorXd& v0,
                  const Eigen::VectorXd& z0 = {});

  /// Adds quadratures (after initialize()): nq integrands, started at 0 and, with
  /// `error_control`, included in the step-size control with tolerances rtol, atol.
  void add_quadrature(int nq, QuadratureRhs rhs, bool error_control, double atol);
  /// Quadrature values at time().
  Eigen::VectorXd quadrature() const;

  /// Forward sensitivities (after initialize(); staggered corrector): initial values
  /// yS0, ypS0 (state size × ns) and typical parameter magnitudes pbar that scale the
  /// sensitivity error weights. Quadrature sensitivities follow the quadrature.
  /// With `error_control` the sensitivities join the local error test (IDAS's
  /// errconS); without it they ride on the steps the state's own test chooses.
  void add_sensitivities(SensitivityResidual res, const Eigen::MatrixXd& yS0,
                         const Eigen::MatrixXd& ypS0, const Eigen::VectorXd& pbar,
                         bool error_control);
  /// State sensitivities dy/dp at time() (state size × ns); needs a step taken.
  Eigen::MatrixXd state_sensitivities() const;
  void add_quadrature_sensitivities(QuadratureSensitivityRhs rhs);
  /// Quadrature sensitivities at time(): nq × ns.
  Eigen::MatrixXd quadrature_sensitivities() const;

  /// Records IDAS adjoint checkpoints every `steps` steps (Hermite interpolation):
  /// after the forward solve, an IdasBackward can be solved over them.
  void record_checkpoints(long steps);

  /// Integrates until `tout` (never past `t_stop`), then interpolates the state at
  /// tout. Returns false on solver failure; error() then says why and at which time.
  /// With `step_budget` > 0 it also returns false, with error() empty, when this
  /// integrator's steps reach the budget before tout (the caller says why).
  bool advance_to(double tout, double t_stop, long step_budget = 0);

  /// The first step for a fresh integrator restarted from the state at time():
  /// the largest first-order step whose local error, ½h²‖ÿ‖ in IDAS's error norm,
  /// stays at a quarter of the tolerance, ÿ read off this integrator's interpolating
  /// polynomial. IDAS's own first step is scaled to ‖ẏ‖ and is orders of magnitude
  /// smaller here; climbing back from it took ~16 steps with a Newton matrix each.
  /// 0 when the polynomial has no second derivative yet (IDAS then chooses).
  double restart_step() const;

  double time() const { return t_; }                       // time of the interpolated state
  double solver_time() const;                              // how far IDAS has stepped
  const Eigen::VectorXd& positions() const { return x_; }  // free dofs at time()
  const Eigen::VectorXd& velocities() const { return v_; }
  const Eigen::VectorXd& internal() const { return z_; }  // internal variables at time()
  const std::string& error() const { return error_; }
  IntegratorStats stats() const;

  struct Impl;

 private:
  friend class IdasBackward;  // solves over this integrator's IDAS memory
  void* idas_memory() const;
  void* sundials_context() const;
  std::unique_ptr<Impl> impl_;
  double t_ = 0;
  Eigen::VectorXd x_, v_, z_;
  std::string error_;
};

}  // namespace kelvin
