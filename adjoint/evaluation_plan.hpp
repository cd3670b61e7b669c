#pragma once
/// \file
/// What the evaluations of one experiment carry from one to the next so that every
/// evaluation at one tolerance scale integrates alike: the adjoint's segment plan,
/// the BDF order cap of `solver.max_order: auto`, and the peaks of λ that set the
/// backward tolerances. A value: a fit problem holds one per experiment and hands it
/// to every evaluation; a fresh one plans again (a copy goes on as the original).
#include <Eigen/Core>
#include <algorithm>

#include "engine/fem_model.hpp"
#include "engine/idas_integrator.hpp"
#include "engine/order_policy.hpp"

namespace kelvin {

class ByteWriter;
class ByteReader;

class EvaluationPlan {
 public:
  /// Simulated seconds per segment, the same for every evaluation: boundaries
  /// that moved with the parameters would make Φ rough, and a fit would stall on
  /// it. `option` > 0 is used as given; 0 means automatic, chosen at the first
  /// evaluation that completes (plan_segments) at each tolerance scale (a fit that
  /// tightens its tolerances takes more steps, so it plans again). Returns 0 for
  /// one segment, and while the choice is still open.
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
  /// (choose_max_order) on `model` by the first run at each scale and kept, so
  /// that every evaluation at one scale steps alike, as the segment plan does.
  int order_cap(const FemModel& model, const IntegratorOptions& options, double t_end,
                const Eigen::VectorXd& x0, const Eigen::VectorXd& v0, double tolerance_scale);
  /// The last probe's outcome (max_order 0 before any).
  const OrderChoice& order_choice() const { return order_choice_; }

  /// Peaks of |λx| and |λv| per unit RMS misfit met by an adjoint pass (0 before
  /// one), renewed when a pass meets λ they mispredict. λ is linear in the misfit,
  /// so later passes set their absolute tolerances from these
  /// (ExperimentRun::set_adjoint_scale) instead of from a guess.
  struct AdjointPeaks {
    double x = 0, v = 0;
  };
  const AdjointPeaks& adjoint_peaks() const { return adjoint_peaks_; }
  void note_adjoint_peaks(const AdjointPeaks& per_rms) { adjoint_peaks_ = per_rms; }

 private:
  // Packed whole for the ranks that do not own the experiment (result_exchange.hpp):
  // every field, in one order for the writer and the reader.
  friend void put(ByteWriter&, const EvaluationPlan&);
  friend void get(ByteReader&, EvaluationPlan&);
  template <class Bytes, class Plan>
  static void fields(Bytes& io, Plan& plan) {
    io(plan.segment_);
    io(plan.planned_scale_);
    io(plan.planned_steps_);
    io(plan.order_choice_);
    io(plan.order_scale_);
    io(plan.adjoint_peaks_);
  }
  double segment_ = -1;       // automatic segment length; < 0 until planned
  double planned_scale_ = 0;  // the tolerance scale segment_ was planned at
  long planned_steps_ = 0;
  OrderChoice order_choice_{0};
  double order_scale_ = 0;  // the tolerance scale order_choice_ was probed at
  AdjointPeaks adjoint_peaks_;
};

}  // namespace kelvin
