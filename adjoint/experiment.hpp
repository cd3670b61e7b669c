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
  /// Automatic segments are sized to half of it (see Experiment::plan_segments).
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
  /// first). A failing simulation (inversion, solver failure) is reported in the
  /// result, not thrown: a fitter backs off from such trial parameters.
  ExperimentResult evaluate(const ParameterMap& map, const Eigen::VectorXd& p,
                            const GradientOptions& options);

  /// Simulated seconds per segment, the same for every evaluation of this
  /// experiment: boundaries that moved with the parameters would make Φ rough, and
  /// a fit would stall on it. `option` > 0 is used as given; 0 means automatic,
  /// chosen at the first evaluation that completes (plan_segments) at each
  /// tolerance scale (a fit that tightens its tolerances takes more steps, so it
  /// plans again). Returns 0 for one segment, and while the choice is still open.
  double segment_length(double option) const { return option > 0 ? option : segment_; }
  bool segments_planned(double option, double tolerance_scale) const {
    return option > 0 || (segment_ >= 0 && tolerance_scale == planned_scale_);
  }
  /// Fixes the automatic plan after an unsegmented run of `steps` steps over
  /// `duration` at `tolerance_scale`: one segment if the run fits the checkpoint
  /// budget, otherwise equal segments of about half the budget each (the margin
  /// lets trial parameters that need more steps still fit). True when the run must
  /// be redone in segments.
  bool plan_segments(long steps, long budget, double duration, double tolerance_scale);
  /// Steps of the planning run (0 before it), raised by later one-segment runs
  /// that took more (note_steps): a one-segment adjoint reserves room for about
  /// these, not for its whole budget.
  long planned_steps() const { return planned_steps_; }
  void note_steps(long steps) { planned_steps_ = std::max(planned_steps_, steps); }

  /// The BDF order cap for `solver.max_order: auto` at `tolerance_scale`: probed
  /// (choose_max_order) by the first run at each scale and kept, so that every
  /// evaluation at one scale steps alike, as the segment plan does.
  int order_cap(const IntegratorOptions& options, double t_end, const Eigen::VectorXd& x0,
                const Eigen::VectorXd& v0, double tolerance_scale);
  /// The last probe's outcome (max_order 0 before any).
  const OrderChoice& order_choice() const { return order_choice_; }

  /// Peaks of |λx| and |λv| per unit RMS misfit met by an adjoint pass (0 before
  /// one), renewed when a pass meets λ they mispredict. λ is linear in the misfit, so
  /// later passes set their absolute tolerances from these
  /// (ExperimentRun::set_adjoint_scale) instead of from a guess.
  struct AdjointPeaks {
    double x = 0, v = 0;
  };
  const AdjointPeaks& adjoint_peaks() const { return adjoint_peaks_; }
  void note_adjoint_peaks(const AdjointPeaks& per_rms) { adjoint_peaks_ = per_rms; }

 private:
  const Scenario& scenario_;
  std::unique_ptr<FemModel> model_;
  MarkerObjective objective_;
  std::vector<ShapeTarget> targets_;
  double segment_ = -1;       // automatic segment length; < 0 until planned
  double planned_scale_ = 0;  // the tolerance scale segment_ was planned at
  long planned_steps_ = 0;
  OrderChoice order_choice_{0};
  double order_scale_ = 0;  // the tolerance scale order_choice_ was probed at
  AdjointPeaks adjoint_peaks_;
};

}  // namespace kelvin
