#pragma once
/// \file
/// Internal to the gradient methods: the state one evaluation of an experiment
/// shares between the objective run, forward sensitivities and the adjoint.
#include <Eigen/SparseCore>
#include <Eigen/SparseLU>
#include <algorithm>
#include <functional>
#include <optional>

#include "adjoint/experiment.hpp"
#include "engine/dae_system.hpp"

namespace kelvin {

struct ExperimentRun {
  ExperimentRun(Experiment& ex, EvaluationPlan& plan, const ParameterMap& map,
                const Eigen::VectorXd& p, const GradientOptions& opt);

  Experiment& ex;
  EvaluationPlan& plan;
  FemModel& model;
  const MarkerObjective& objective;
  const ParameterMap& map;
  const Eigen::VectorXd& p;
  const GradientOptions& opt;
  IntegratorOptions iopt;
  ParamDerivatives deriv;
  DaeSystem dae;  // K, D and mass solves at arbitrary states
  int n = 0;
  double t0 = 0, t_end = 0;
  Eigen::VectorXd x0, v0;
  Eigen::VectorXd z0;        // internal variables, relaxed at x0 (empty without them)
  Eigen::Matrix3Xd x, v, a;  // full nodal fields of the last expand()
  Eigen::VectorXd z;         // and its internal variables (empty: relaxed, a static state)
  double t_state = 0;        // their time
  int state_size() const { return dae.size(); }

  /// Observation parameters whose gradient this run integrates along with Φ
  /// (MarkerObjective's θ; 0 without a gradient or without observation blocks).
  int observation_count = 0;
  /// Adds a finished integrator's quadratures to `result`: Φ per marker and, with
  /// observation_count, ∫ ∂g/∂θ dt.
  void add_quadratures(const IdasIntegrator& integ, ExperimentResult& result) const;

  /// t₀, the shape targets' times inside the run, and t_end: the objective and
  /// adjoint passes restart at these (the adjoint's λx jumps at a target time);
  /// forward sensitivities, one integrator for the whole run, stop there without a
  /// restart, so their Φ differs from the others' within the integration tolerance.
  std::vector<double> fixed_times() const;
  /// Segment boundaries t0 = T₀ < … < T_S = t_end: the fixed times and, once the
  /// experiment's automatic plan is made, its equal segments (a boundary close to a
  /// fixed time is left out).
  std::vector<double> boundaries() const;
  /// Φ_k of the shape targets at time t, added to result.phi_targets, from the free
  /// positions at t; with `gradient`, their ∂Φ/∂x (free dofs) is added there instead.
  void add_targets(double t, const Eigen::VectorXd& x_free, ExperimentResult& result);
  void add_target_gradient(double t, const Eigen::VectorXd& x_free, double* gradient);
  /// visit(k, target, x) for every target at time t, with the full positions x
  /// expanded once from x_free.
  template <class Visit>
  void visit_targets_at(double t, const Eigen::VectorXd& x_free, Visit visit);
  /// Most steps one segment's Hermite points may hold (GradientOptions::checkpoint_steps).
  long checkpoint_budget() const;
  /// True when this evaluation decides the experiment's automatic segment plan.
  bool planning() const { return !plan.segments_planned(opt.segment, opt.tolerance_scale); }
  /// Decides it: one plain run over the whole duration (no Hermite points, so no
  /// memory that grows with the duration) into `plain` (Φ, steps), whose step
  /// count EvaluationPlan::plan_segments turns into segments. False (with
  /// plain.error) when that run fails.
  bool plan_segments(ExperimentResult& plain);

  void expand(double t, const double* y, const double* yp);
  /// A fresh integrator at (t, y) with the Φ quadrature attached: every forward
  /// pass of an evaluation is built here, so that they take identical steps. A
  /// segment restart passes the first step the previous segment's integrator
  /// proposed (IdasIntegrator::restart_step); 0 keeps the scenario's choice.
  std::unique_ptr<IdasIntegrator> start(double t, const Eigen::VectorXd& x_free,
                                        const Eigen::VectorXd& v_free,
                                        const Eigen::VectorXd& z_internal, double first_step = 0);
  /// Attaches the state sensitivities dy/dp_j (every entry j of p) to an integrator
  /// fresh from start() at t₀, and returns their initial values yS0 (2n × p.size()):
  /// forward-sensitivity gradients and marker sensitivities share this one setup.
  /// `error_control`: see IdasIntegrator::add_sensitivities.
  Eigen::MatrixXd add_sensitivities(IdasIntegrator& integ, bool error_control);
  /// The entries add_sensitivities carries, in its columns' order: the model's, or
  /// those of GradientOptions::sensitivity_entries (observation entries do not move
  /// the model and are left out).
  std::vector<int> sensitivity_entries() const {
    const std::vector<int> model = map.model_entries();
    if (!opt.sensitivity_entries) return model;
    std::vector<int> out;
    for (int j : *opt.sensitivity_entries)
      if (std::find(model.begin(), model.end(), j) != model.end()) out.push_back(j);
    return out;
  }
  /// Integrates segments 0 … count−1 of T from (x₀, v₀), each restarted with the
  /// first step its predecessor proposed, and adds their Φ (the targets at t₀ and at
  /// the segments' ends included) and steps to `result`;
  /// `segment_done(k, integ)` sees every finished segment. False on failure.
  bool integrate_segments(const std::vector<double>& T, int count, ExperimentResult& result,
                          const std::function<void(int, IdasIntegrator&)>& segment_done = {});
  /// Integrates to t1; false (with result.error, t_reached) on failure or interrupt.
  /// IDAS never steps past t_stop (default t1); a later t_stop keeps the steps of a
  /// run to t_stop and interpolates the state at t1.
  bool advance(IdasIntegrator& integ, double t1, ExperimentResult& result,
               std::optional<double> t_stop = std::nullopt);
  /// ∂R/∂p_j over the free dofs for every entry j of p, at the current x, v, a, z,
  /// followed by the internal variables' rows ∂(z' − f)/∂p_j (n + num_internal rows).
  bool param_vectors(Eigen::MatrixXd& B);
  /// out[j] += scale · (Σ_{s,e} λ_eᵀ ∂R_e/∂q_{s,e} + λzᵀ ∂(z' − f)/∂q_{s,e}) ∂q_{s,e}/∂p_j
  /// at the current x, v, a, z for every entry j of p (with dP/dq from `cached` when
  /// given, see ParamDerivatives::for_each; lambda_z null at a static state): the
  /// adjoint integrates p.size() quadratures, not one per slot and element (a body
  /// force has thousands of slot-element pairs).
  bool contract(const double* lambda, double scale, double* out,
                const ElementTangents* cached = nullptr, const double* lambda_z = nullptr);
  /// ∂q_{s,e}/∂p at p, which stays put during an evaluation: (j, ∂q/∂p_j) pairs of
  /// slot s in element e in dependencies[dependency_ptr[s·ne + e] … [s·ne + e + 1]).
  std::vector<int> dependency_ptr;
  std::vector<std::pair<int, double>> dependencies;

  /// Typical magnitudes of λx and λv, for the backward absolute tolerances, and the
  /// RMS misfit they belong to. From the experiment's last adjoint pass scaled by
  /// the misfit when there was one; otherwise a guess (λx ~ ∫ ∂g/∂x dt ~ RMS · T,
  /// λv ~ λx · T / m, m a mean nodal mass) that the backward pass checks against
  /// the λ it meets and corrects (backward_segment).
  double lambda_x_ref = 0, lambda_v_ref = 0, misfit_rms = 0;
  bool lambda_refs_missed = false;  // a backward pass was solved again with smaller ones
  void set_adjoint_scale(const ExperimentResult& result);

  /// Sensitivity of a static initial state, x₀_p = −K₀⁻¹ ∂R/∂p (zero from rest).
  bool static_initial() const { return ex.scenario().static_initial; }
  void factor_static_stiffness();
  std::optional<Eigen::SparseLU<Eigen::SparseMatrix<double>>> K0;
};

/// The methods, each filling `result` (Φ, gradient) for one experiment.
void evaluate_objective(ExperimentRun& run, ExperimentResult& result);
void evaluate_forward_sensitivities(ExperimentRun& run, ExperimentResult& result);
void evaluate_adjoint(ExperimentRun& run, ExperimentResult& result);

}  // namespace kelvin
