// The trials of a line search: which are simulated at all (next to the best, too
// far from it, or stuck on Φ's integration noise), which are accepted, and what a
// stage's plateau and Φ's accuracy are measured from.
#include <fmt/format.h>

#include <algorithm>

#include "fit/fit_context.hpp"

namespace kelvin::fit_detail {
namespace {

/// p − best entry by entry: for linear parameters relative to the best's size or the
/// parameter's unit (ParameterMap::units), whichever is larger; absolute for log ones
/// (that is, relative in q).
Eigen::VectorXd offset_from_best(const Context& c, const Eigen::VectorXd& p) {
  const ParameterMap& map = c.problem.map();
  Eigen::VectorXd d = p - c.outcome.p;
  for (long j = 0; j < p.size(); ++j)
    if (!map.is_log(static_cast<int>(j))) d[j] /= std::max(std::abs(c.outcome.p[j]), c.unit[j]);
  return d;
}

/// True when every entry of p is within kStallStep of the best point.
bool next_to_best(const Context& c, const Eigen::VectorXd& p) {
  return offset_from_best(c, p).lpNorm<Eigen::Infinity>() <= kStallStep;
}

}  // namespace

/// Distance of p from the best point, in offset_from_best's units.
double distance_to_best(const Context& c, const Eigen::VectorXd& p) {
  return offset_from_best(c, p).norm();
}

/// Norm of the gradient with the components that push against an active bound
/// removed: the first-order optimality measure of a box-constrained problem.
double projected_norm(const Eigen::VectorXd& g, const Eigen::Ref<const Eigen::VectorXd>& p,
                      const Eigen::VectorXd& lo, const Eigen::VectorXd& hi) {
  double sum = 0;
  for (long j = 0; j < g.size(); ++j) {
    const bool blocked = (p[j] <= lo[j] && g[j] > 0) || (p[j] >= hi[j] && g[j] < 0);
    if (!blocked) sum += g[j] * g[j];
  }
  return std::sqrt(sum);
}

namespace {

/// The history record of evaluation `ev` at p (not yet numbered as accepted or
/// given its iteration), and in g the objective's gradient there (misfit's plus the
/// parameter terms'; zero after a failure). Counts a failure.
FitRecord record_of(Context& c, const Eigen::VectorXd& p, const Evaluation& ev,
                    double tolerance_scale, Eigen::VectorXd& g) {
  FitRecord r;
  r.tolerance_scale = tolerance_scale;
  r.evaluation = c.options.first_evaluation + c.outcome.evaluations + 1;
  r.p = p;
  // Rank 0's clock: max_seconds must stop every rank at the same evaluation.
  r.seconds = c.problem.communicator().from_root(
      c.options.seconds_offset +
      std::chrono::duration<double>(std::chrono::steady_clock::now() - c.start).count());
  r.ok = ev.ok;
  g = Eigen::VectorXd::Zero(p.size());
  if (ev.ok) {
    r.misfit = ev.phi;
    r.rms = ev.rms;
    for (const auto& term : c.terms) r.penalty += term->value(p, &g);
    if (ev.gradient.size()) g += ev.gradient;
    r.objective = r.misfit + r.penalty;
    r.gradient_norm = ev.gradient.size() ? g.norm() : 0;
  } else {
    // Real2Sim returns DBL_MAX here; a finite huge value keeps every NLopt
    // algorithm's bookkeeping sane while the line search backs off.
    r.error = ev.error;
    r.objective = kFailedObjective;
    ++c.outcome.failures;
  }
  return r;
}

/// Φ's accuracy at the scenario's tolerances where no coarser stage handed over
/// (a fit in one stage), measured once, when a line search first looks stuck:
/// the best point's Φ again at kStageRatio× tighter tolerances. Without it such a
/// fit could not tell a stall from a hard line search: on the bench bar with its
/// scenario at rtol 1e-3 it spent its last 10 evaluations (24 s of 70), all
/// rejected, their RMS within 8 % of the best.
void probe_accuracy(Context& c) {
  c.probed = true;
  if (c.outcome.evaluations >= c.budget) return;
  GradientOptions gopt = c.options.gradient;
  gopt.tolerance_scale *= c.tolerance_scale / kStageRatio;
  gopt.method = GradientMethod::kNone;
  const Evaluation ev = c.problem.evaluate(c.outcome.p, gopt);
  Eigen::VectorXd g;
  FitRecord r = record_of(c, c.outcome.p, ev, gopt.tolerance_scale, g);
  r.iteration = c.iteration;
  ++c.outcome.evaluations;
  c.outcome.history.push_back(r);
  if (c.options.on_evaluation) c.options.on_evaluation(r);
  if (ev.interrupted) {
    c.outcome.interrupted = true;
    throw nlopt::forced_stop();
  }
  if (!ev.ok || !(ev.phi > 0)) return;
  c.accuracy = std::abs(c.outcome.best.misfit - ev.phi) / ev.phi;
  if (c.options.on_progress)
    c.options.on_progress(fmt::format(
        "  line search stuck: Φ at {:g}× tighter tolerances differs by {:.2g} % at the best point",
        kStageRatio, 100 * c.accuracy));
}

/// Predicted gains above this are not worth a simulation to compare with Φ's accuracy,
/// which is below it at any tolerance a fit runs at.
constexpr double kGainWorthProbing = 1e-2;

/// After an accepted move in Gauss–Newton-scaled parameters at the last stage: when
/// the Gauss–Newton model predicts a gain from the new best point within Φ's
/// accuracy, no further trial can show one, and the fit has converged. On the
/// diagnosis case V01 its nominal fit reached 0.8148 mm in its first Gauss–Newton
/// step and then spent 11 evaluations (15 of its 20 minutes), all but one rejected,
/// to reach 0.8146 mm: a gain of 0.05 % against an accuracy of 0.068 %.
void check_predicted_gain(Context& c, const Eigen::VectorXd& g) {
  const double gain = predicted_gain(c, g);
  if (!(gain < kGainWorthProbing)) return;
  if (c.accuracy == 0 && !c.probed) {
    try {
      probe_accuracy(c);
    } catch (const nlopt::forced_stop&) {
      return;  // interrupted: objective() stops the run
    }
  }
  if (c.accuracy > 0 && gain < c.accuracy) c.gain_within_accuracy = gain;
}

}  // namespace

/// The optimiser sees the objective times a scale fixed at the first evaluation.
/// Φ in m²·s is ~1e-9 for millimetre misfits, below the absolute gradient
/// tolerances inside NLopt's L-BFGS, which would stop at once. And L-BFGS's
/// first trial step is the negative gradient: scaled to length ½ it changes a
/// log-parameter by at most a factor e^½, where an unscaled step jumped a
/// 2×-off stiffness 100× into a rigid, flat region. Derivative-free fits
/// normalise by the first value instead.
double objective_scale(bool ok, double objective, const Eigen::VectorXd& gradient,
                       double first_step) {
  if (!ok || !(objective > 0)) return 1;
  const double g = gradient.norm();
  return g > 0 ? first_step / g : 1 / objective;
}

double objective(const std::vector<double>& x, std::vector<double>& grad, void* data) {
  auto& c = *static_cast<Context*>(data);
  // NLopt's L-BFGS notices force_stop only between line-search trials; throwing
  // forced_stop here ends the run before another simulation starts.
  if (c.outcome.interrupted || c.budget_spent) throw nlopt::forced_stop();
  const Eigen::Map<const Eigen::VectorXd> xv(x.data(), static_cast<long>(x.size()));
  const Eigen::VectorXd p =
      c.basis.size() == 0
          ? Eigen::VectorXd(xv.cwiseProduct(c.unit))
          : Eigen::VectorXd((c.origin + c.basis * xv).cwiseMax(c.lo).cwiseMin(c.hi));
  if (!c.remeasure && c.outcome.best.evaluation != 0) {
    // NLopt begins every restart by evaluating its start point, which is the best
    // point, already simulated at these tolerances: no simulation is spent on it.
    if (p == c.outcome.p && (grad.empty() || c.best_g.size() == p.size())) {
      const Eigen::VectorXd gx = c.basis.size() ? Eigen::VectorXd(c.basis.transpose() * c.best_g)
                                                : Eigen::VectorXd(c.best_g.cwiseProduct(c.unit));
      if (c.scale == 0) c.scale = objective_scale(true, c.outcome.best.objective, gx, c.first_step);
      if (!grad.empty()) Eigen::Map<Eigen::VectorXd>(grad.data(), p.size()) = c.scale * gx;
      return c.scale * c.outcome.best.objective;
    }
    // Near a minimum NLopt's L-BFGS backtracks by 100× per trial down to steps of
    // 1e-15, though Φ's integration noise (2 % of Φ at the benchmark bar's plateau
    // at rtol 1e-4, from one trial to the next) hides any decrease below about
    // 1e-5: five to nine simulations per stalled line search, a fifth of that
    // fit's budget, bought nothing. The run stops instead, and the restart loop
    // goes on as after any stalled line search.
    if (c.rejected_in_row >= kMaxRejections && c.tolerance_scale <= 1 && c.accuracy == 0 &&
        !c.probed && c.opt->get_algorithm() == nlopt::LD_LBFGS) {
      try {
        probe_accuracy(c);
      } catch (const nlopt::forced_stop&) {
        throw;
      } catch (...) {
        c.error = std::current_exception();
        throw nlopt::forced_stop();
      }
      if (c.outcome.evaluations >= c.budget) {
        c.budget_spent = true;
        throw nlopt::forced_stop();
      }
    }
    const bool stuck =
        (c.tolerance_scale > 1 || c.accuracy > 0) && c.rejected_in_row >= kMaxRejections;
    if ((p != c.outcome.p && next_to_best(c, p)) || stuck) {
      c.stalled = true;
      throw nlopt::forced_stop();
    }
    if (const double d = distance_to_best(c, p);
        d > std::max(kLongStep, kLongStepGrowth * c.last_distance)) {
      if (c.options.on_progress)
        c.options.on_progress(fmt::format(
            "  trial refused unsimulated: {:.2g} from the best point (last move {:.2g}); "
            "backing off",
            d, c.last_distance));
      if (!grad.empty()) std::fill(grad.begin(), grad.end(), 0.0);
      return kFailedObjective;
    }
  }
  try {
    GradientOptions gopt = c.options.gradient;
    gopt.tolerance_scale *= c.tolerance_scale;
    // A failed trial makes the line search back off (see limit_trial_steps).
    limit_trial_steps(gopt, c.best_steps);
    if (grad.empty()) gopt.method = GradientMethod::kNone;
    const Evaluation ev = c.problem.evaluate(p, gopt);

    Eigen::VectorXd g;
    FitRecord r = record_of(c, p, ev, gopt.tolerance_scale, g);
    ++c.outcome.evaluations;
    const bool interrupted = ev.interrupted;
    // After a tolerance change the best's value is re-measured at its own point.
    const bool remeasure = c.remeasure && ev.ok;
    c.remeasure = false;
    bool moved = false;  // an accepted move away from the previous best
    if (ev.ok &&
        (remeasure || c.outcome.best.evaluation == 0 || r.objective < c.outcome.best.objective)) {
      // The first evaluation is the start point (iteration 0, or the resumed iterate).
      r.accepted = true;
      if (remeasure) {
        c.remeasured = r.objective;
        if (std::isfinite(c.handover_objective) && r.objective > 0)
          c.accuracy = std::abs(c.handover_objective - r.objective) / r.objective / kStageRatio;
        const double start = c.options.start_objective;
        if (c.tolerance_scale <= 1 && c.options.precision > 0 && std::isfinite(start) &&
            r.objective > (1 - c.options.precision) * start)
          c.coarse_gain_lost = true;
      }
      if (ev.gradient.size()) {
        c.best_g = g;
        c.best_gradient = projected_norm(g, p, c.lo, c.hi);
        if (c.outcome.best.evaluation == 0) c.start_gradient = c.best_gradient;
      }
      moved = c.outcome.best.evaluation != 0 && !remeasure;
      if (moved) {
        ++c.iteration;
        c.last_move = ((p - c.outcome.p).cwiseQuotient(c.unit)).norm();
        c.last_distance = distance_to_best(c, p);
      }
      c.best_steps = 0;
      for (const auto& e : ev.experiments)
        c.best_steps = std::max(c.best_steps, e.forward_stats.steps);
      r.iteration = c.iteration;
      c.outcome.best = r;
      c.outcome.p = p;
    } else {
      r.iteration = c.iteration;
    }
    c.rejected_in_row = r.accepted ? 0 : c.rejected_in_row + 1;
    c.outcome.history.push_back(r);
    if (c.outcome.best.evaluation != 0 && r.accepted) {
      c.stage_best.push_back(c.outcome.best.objective);
      const size_t k = c.stage_best.size();
      if (k > kPlateauWindow) {
        const double before = c.stage_best[k - 1 - kPlateauWindow], now = c.stage_best.back();
        const double gain = (before - now) / std::abs(now);
        const double floor =
            std::max(c.tolerance_scale > 1 ? kCoarsePlateauGain : c.accuracy, c.options.precision);
        if (floor > 0 && gain < floor) c.plateau = true;
      }
    }
    if (c.options.on_evaluation) c.options.on_evaluation(r);
    if (r.accepted && moved && ev.gradient.size() && c.basis.size() && c.tolerance_scale <= 1 &&
        !interrupted)
      check_predicted_gain(c, g);
    if (c.options.gauss_newton_start && c.outcome.evaluations == 1 && r.accepted &&
        ev.gradient.size() && c.opt->get_algorithm() == nlopt::LD_LBFGS)
      c.gauss_newton_start_pending = true;
    const Eigen::VectorXd gx = c.basis.size() ? Eigen::VectorXd(c.basis.transpose() * g)
                                              : Eigen::VectorXd(g.cwiseProduct(c.unit));
    if (c.scale == 0) c.scale = objective_scale(ev.ok, r.objective, gx, c.first_step);
    if (!grad.empty()) Eigen::Map<Eigen::VectorXd>(grad.data(), p.size()) = c.scale * gx;
    if (interrupted) {
      c.outcome.interrupted = true;
      c.opt->force_stop();
    } else if (c.plateau || c.gauss_newton_start_pending || c.coarse_gain_lost ||
               std::isfinite(c.gain_within_accuracy)) {
      c.opt->force_stop();
    } else if (c.outcome.evaluations >= c.budget) {
      // NLopt's L-BFGS checks maxeval only between iterations.
      c.budget_spent = true;
      c.opt->force_stop();
    } else if (c.options.max_seconds > 0 && r.seconds >= c.options.max_seconds) {
      c.budget_spent = c.time_spent = true;
      c.opt->force_stop();
    }
    return ev.ok ? c.scale * r.objective : kFailedObjective;
  } catch (...) {
    c.error = std::current_exception();
    c.opt->force_stop();
    return kFailedObjective;
  }
}

}  // namespace kelvin::fit_detail
