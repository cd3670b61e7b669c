#pragma once
/// \file
/// One captured motion of the specimen (a scenario with observed marker tracks) and
/// what a gradient evaluation needs of it: its model, its objective, the parameter
/// derivatives of its residual, and the initial state with its sensitivity.
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <algorithm>
#include <atomic>
#include <memory>
#include <string>
#include <vector>

#include "adjoint/evaluation_plan.hpp"
#include "adjoint/marker_objective.hpp"
#include "adjoint/parameter_map.hpp"
#include "adjoint/shape_target.hpp"
#include "engine/fem_model.hpp"
#include "engine/idas_integrator.hpp"
#include "engine/order_policy.hpp"
#include "engine/param_derivatives.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {

enum class GradientMethod { kNone, kForward, kAdjoint };
GradientMethod parse_gradient_method(const std::string& name);  // adjoint | forward | none
const char* to_string(GradientMethod m);

struct GradientOptions {
  GradientMethod method = GradientMethod::kAdjoint;
  /// Most IDAS steps whose Hermite points one adjoint segment stores; 0 = default.
  /// Automatic segments are sized to half of it (see EvaluationPlan::plan_segments).
  long checkpoint_steps = 0;
  double segment = 0;          // simulated seconds per adjoint segment; 0 = automatic
  double tolerance_scale = 1;  // multiplies the scenario's rtol and atol (the fit's stages)
  /// An experiment whose forward run takes more IDAS steps than this fails
  /// (0: no limit). The fit bounds its line-search trials so (see run_fit).
  long max_steps = 0;
  /// Paces that limit: by the time a fraction f of the run's duration is reached,
  /// more than max_steps · max(f, step_pace_floor) steps fail the run already
  /// (1: only the total counts). With the floor at 1/k and max_steps k times a
  /// reference run's steps, a run that takes no more steps than the reference
  /// never fails, however its steps are spread in time.
  double step_pace_floor = 1;
  const std::atomic<bool>* interrupt = nullptr;
  /// Forward sensitivities of these entries only (null: every model entry); the other
  /// model entries' columns stay zero. A diagnosis screens each candidate in a model
  /// of its own and needs only that candidate's columns there.
  const std::vector<int>* sensitivity_entries = nullptr;
};

/// Default checkpoint budget (steps) for a state of `state_size` entries: 512 MiB of
/// Hermite points (y and y', 16 bytes per entry each), at least 200. A run that
/// fits is one segment, integrated once; a longer one is cut into segments, each
/// integrated twice (pass 1 keeps only the boundary states) and restarted at BDF
/// order 1, so memory stays flat in the run's length. 64 MiB cut the diagnosis bar
/// V01 (1512 tets, 5.9k steps for 2.2 s at rtol 1e-4) into 8 segments: Φ + adjoint
/// cost 2.57× Φ alone, where one segment costs 2.15×.
inline long default_checkpoint_steps(int state_size) {
  const long per_point = 16L * std::max(state_size, 1);
  return std::max((512L << 20) / per_point, 200L);
}

/// Ranks that did not run the experiment receive it packed (result_exchange.cpp packs
/// every field: a new one goes there too).
struct ExperimentResult {
  bool ok = false;
  std::string error;  // why the simulation failed (names the time)
  double t_reached = 0;
  double t_furthest = 0;  // latest time any pass reached: the progress the step limit is paced by
  Eigen::VectorXd phi_per_marker;  // Φᵢ
  Eigen::VectorXd phi_targets;     // Φ_k of each shape target (Experiment::targets())
  double phi = 0, rms = 0;         // Σ Φᵢ + Σ Φ_k and the RMS distance (m) over both
  Eigen::VectorXd gradient;        // dΦ/dp (empty without a gradient)
  Eigen::VectorXd dphi_dtheta;     // ∫ ∂g/∂θ dt over the observation vector, with a gradient
  IntegratorStats forward_stats, backward_stats;
  long backward_steps = 0;
  int segments = 1;
  double seconds = 0;
};

class Experiment {
 public:
  /// The scenario must outlive the experiment and have observed marker tracks or
  /// shape targets (objective.targets, which belong to this experiment's motion).
  Experiment(const Scenario& scenario, const ObjectiveSpec& objective);
  Experiment(Scenario&&, const ObjectiveSpec&) = delete;

  const Scenario& scenario() const { return scenario_; }
  FemModel& model() { return *model_; }
  const FemModel& model() const { return *model_; }
  const MarkerObjective& objective() const { return objective_; }
  MarkerObjective& objective() { return objective_; }
  const std::vector<ShapeTarget>& targets() const { return targets_; }

  /// What Φ is measured against: Σᵢ wᵢTᵢ over the markers' observed time plus
  /// Σ_k w_k · coordinates over the targets (m² s of Φ per m² of mean square distance).
  double objective_weight() const;
  /// The RMS distance over markers and targets, sqrt(2Φ / objective_weight()).
  double rms(const Eigen::VectorXd& phi_per_marker, const Eigen::VectorXd& phi_targets) const;

  /// Sets the model's material and the objective's observation parameters to p.
  void apply(const ParameterMap& map, const Eigen::VectorXd& p);

  /// Φ and, on request, dΦ/dp at the map's parameters p (applied to the model
  /// first), integrated as `plan` says (and planned there on its first use). A
  /// failing simulation (inversion, solver failure) is reported in the result, not
  /// thrown: a fitter backs off from such trial parameters.
  ExperimentResult evaluate(const ParameterMap& map, const Eigen::VectorXd& p,
                            const GradientOptions& options, EvaluationPlan& plan);

 private:
  const Scenario& scenario_;
  std::unique_ptr<FemModel> model_;
  MarkerObjective objective_;
  std::vector<ShapeTarget> targets_;
};

}  // namespace kelvin
