// The adjoint gradient with IDAS ASA. For F = [x' − v ; R(t, x, v, v', z; q) ; z' − f]
// the adjoint λ = (λx, λv, λz) solves, backward from λ(T) = 0,
//   λx' − Kᵀλv + f_xᵀλz + ∂g/∂x = 0,   M λv' + λx − Dᵀλv = 0,   λz' − K_xzᵀλv + f_zᵀλz = 0
// (no λz without internal variables), and
//   dΦ/dq = −∫ (λvᵀ ∂R/∂q − λzᵀ ∂f/∂q) dt + (λx + z₀,ₓᵀ λz)(t₀)ᵀ ∂x₀/∂q,
// the last term from a static initial state (one solve with K₀ᵀ, Real2Sim Eq. 14; z₀ is
// relaxed at x₀). IDAS integrates the backward quadrature from q(T) = 0 down to t₀,
// so q(t₀) is the integral term itself.
//
// Segments: the forward pass stores one state per segment boundary (in a temporary
// file, see BoundaryStates); each segment is then re-integrated from its start,
// storing the Hermite points of all its steps, and solved backward, λ being
// continuous across the boundary (F_y' is the identity/mass, so λ(T_k⁻) = λ(T_k⁺))
// except at a shape target's time, where Φ_k(x(T_k)) makes λx jump by ∂Φ_k/∂x.
// Segments take the place of IDAS's own checkpoints within a run (see below); their
// length is fixed per experiment (EvaluationPlan::segment_length).
// The forward model restarts at the same boundaries in every pass, so the gradient
// is exact for the trajectory whose Φ is reported.
#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "adjoint/experiment_run.hpp"
#include "base/error.hpp"
#include "engine/idas_backward.hpp"
#include "engine/schur_solver.hpp"
#include "engine/state_vector.hpp"

namespace kelvin {
namespace {

struct Backward {
  ExperimentRun& run;
  int n;
  DaeSystem dae;  // tangents at forward states (its own scratch; the forward pass keeps running)
  SchurSolver schur{dae};
  double cached_t = NAN;
  Eigen::VectorXd cached_y, gx;
  mutable Eigen::VectorXd kt, dt;     // Kᵀλv, Dᵀλv
  mutable ElementSlots slots;         // transpose_multiply's workspace
  EvaluationPlan::AdjointPeaks peak;  // of |λx|, |λv| at the steps taken
  Eigen::Matrix3Xd x, v;

  explicit Backward(ExperimentRun& r) : run(r), n(r.n), dae(r.model), kt(r.n), dt(r.n) {}

  bool cached_at(double t, const double* y) const {
    return t == cached_t && std::memcmp(cached_y.data(), y, sizeof(double) * cached_y.size()) == 0;
  }

  /// Element tangents, dP/dq and ∂g/∂x at the forward state (t, y), computed once
  /// per state: Newton iterations at one backward time reuse them, K and D are
  /// assembled from them only for a new Newton matrix, and the quadrature at the
  /// converged step (same state) contracts the stored dP/dq instead of evaluating
  /// every material a second time.
  bool at(double t, const double* y) {
    if (cached_at(t, y)) return true;
    cached_t = NAN;
    if (!dae.element_tangents(t, y, true)) return false;
    run.model.expand(t, y, nullptr, x, v);
    gx.setZero(n);
    run.objective.add_gradient(t, run.model, x, gx.data());
    cached_t = t;
    cached_y = Eigen::Map<const Eigen::VectorXd>(y, dae.size());
    return true;
  }

  /// rB = [λx' − Kᵀλv + f_xᵀλz + g_x ; M λv' + λx − Dᵀλv ; λz' − K_xzᵀλv + f_zᵀλz].
  void residual(const double* l, const double* lp, double* r) const {
    run.model.transpose_multiply(dae.tangents(), l + n, kt.data(), dt.data(), slots);
    for (int c = 0; c < n; ++c) {
      r[c] = lp[c] - kt[c] + gx[c];
      r[n + c] = l[c] - dt[c];
    }
    for (int c = 2 * n; c < dae.size(); ++c) r[c] = lp[c];
    run.model.mass_multiply(lp + n, r + n);
    dae.add_internal_adjoint_terms(l, r);
  }

  /// λ' consistent with λ at the cached state.
  void consistent_derivative(const double* l, double* lp) {
    const int size = dae.size();
    std::vector<double> r(size);
    std::fill(lp, lp + size, 0.0);
    residual(l, lp, r.data());  // with λ' = 0
    for (int i = 0; i < n; ++i) lp[i] = -r[i];
    for (int i = 2 * n; i < size; ++i) lp[i] = -r[i];
    Eigen::VectorXd rhs = -Eigen::Map<Eigen::VectorXd>(r.data() + n, n);
    dae.mass_solve(rhs.data(), lp + n);
  }
};

/// Backward absolute tolerances: rtol × this × the typical |λx|, |λv|
/// (ExperimentRun::lambda_x_ref, lambda_v_ref, the peaks of the last pass). On the
/// bench bar (2 s), against a backward pass converged in its tolerances over the
/// same forward steps, and backward steps per forward step:
///   factor | rtol 1e-3, 0.25 mm | rtol 1e-4, 0.25 mm | rtol 1e-4, 0.024 mm
///   0.1    | 4 %, 2.0           | 0.4 %, 2.8         | 3 %, 2.0
///   0.3    | 12 %, 1.3          | 0.8 %, 1.8         | 9 %, 1.5
///   1      | 29 %, 0.7          | 4 %, 1.0           | 26 %, 1.1
/// (largest relative error of the four components). At rtol 1e-6 all three agree
/// to 1e-6 and with forward sensitivities to 5e-4; 1 saves 12 % of the steps there.
constexpr double kAdjointAtolFactor = 0.3;

/// The backward relative tolerance over the forward one when the order cap is 2 or
/// less (lightly damped bodies, engine/order_policy.hpp). BDF2's global error at a
/// given local tolerance is larger than BDF3–5's, and the adjoint's shows it: on the
/// diagnosis bar V01 (rtol 1e-4, 2×-off start) the gradient's largest component was
/// 17 % off one converged at rtol 1e-6 with the backward pass at the forward's rtol,
/// 3 % with it at 1/10 (4.5k instead of 2.4k backward steps, +27 % time), 0.6 % at
/// 1/100 (10.3k); the forward trajectory's own error contributed under 1 %.
constexpr double kLowOrderBackwardRtolScale = 0.1;

/// A backward pass that met λ smaller than its tolerances assumed by more than this
/// factor ran with its error control effectively off, and is solved again with
/// tolerances from the λ it met. Measured on the bench bar at its 0.25 mm shelf
/// (rtol 1e-3): the guessed λv was 4·10⁴× too large, the pass took 102 steps for
/// 2 s of 35 Hz oscillation, and its gradient had the wrong sign in λ and μ;
/// tolerances 10× looser than intended still gave a wrong gradient (22 steps).
constexpr double kLooseTolerance = 3;

/// True when `a` exceeds `b` by more than kLooseTolerance.
bool beyond(double a, double b) {
  return a > kLooseTolerance * b;
}

/// Solves one segment backward from (T1, λ) to T0; adds −∫λvᵀ∂R/∂p dt to dphi_dp and
/// raises `seen` to the peaks of |λx|, |λv| it met.
bool backward_segment(ExperimentRun& run, IdasIntegrator& forward, double T0, double T1,
                      Eigen::VectorXd& lambda, Eigen::VectorXd& dphi_dp,
                      EvaluationPlan::AdjointPeaks& seen, ExperimentResult& result) {
  const int n = run.n;
  Backward b(run);
  BackwardProblem problem;
  problem.schur = &b.schur;
  problem.residual = [&b](double t, const double* y, const double* l, const double* lp, double* r) {
    if (!b.at(t, y)) return false;
    b.residual(l, lp, r);
    return true;
  };
  problem.quadrature = [&b, &run, n](double t, const double* y, const double* yp, const double* l,
                                     double* q) {
    run.expand(t, y, yp);
    const Eigen::Map<const Eigen::VectorXd> lam(l, 2 * n);
    b.peak.x = std::max(b.peak.x, lam.head(n).lpNorm<Eigen::Infinity>());
    b.peak.v = std::max(b.peak.v, lam.tail(n).lpNorm<Eigen::Infinity>());
    std::fill(q, q + run.map.size(), 0.0);
    const ElementTangents* cached = b.cached_at(t, y) ? &b.dae.tangents() : nullptr;
    return run.contract(l + n, 1.0, q, cached, l + 2 * n);
  };
  problem.jacobian = [&b](double t, double cj, const double* y) {
    if (!b.at(t, y)) return false;
    b.dae.assemble_from_tangents();
    b.schur.assemble_from_last(-cj);
    return true;
  };

  const int size = run.state_size();
  Eigen::VectorXd lambda_rate(size);
  // λz's typical size: its rows λz' = K_xzᵀλv − f_zᵀλz settle at |K_xz| |λv| / |f_z|.
  double lambda_z_per_v = 0;
  {
    Eigen::VectorXd yT(size);
    yT << forward.positions(), forward.velocities(), forward.internal();
    if (!b.at(T1, yT.data())) throw Error("the final state is inadmissible");
    b.consistent_derivative(lambda.data(), lambda_rate.data());
    const InternalLinearisation& lin = b.dae.internal();
    for (size_t k = 0; k < lin.Kxz.size(); ++k)
      lambda_z_per_v =
          std::max(lambda_z_per_v, lin.Kxz[k].cwiseAbs().maxCoeff() /
                                       std::max(lin.fz[k].cwiseAbs().maxCoeff(), 1e-300));
  }
  IdasBackward backward(forward, std::move(problem), T1, lambda, lambda_rate,
                        static_cast<int>(dphi_dp.size()), run.iopt.max_order, run.iopt.max_steps);

  // Each attempt restarts from λ(T1) over the same stored forward steps.
  const double rtol = run.iopt.rtol * (run.iopt.max_order <= 2 ? kLowOrderBackwardRtolScale : 1.0);
  Eigen::VectorXd atol(size);
  for (int attempt = 0;; ++attempt) {
    atol.head(n).setConstant(rtol * kAdjointAtolFactor * run.lambda_x_ref);
    atol.segment(n, n).setConstant(rtol * kAdjointAtolFactor * run.lambda_v_ref);
    // Uncoupled (a branch at zero modulus), λz stays 0: any finite tolerance serves.
    atol.tail(size - 2 * n)
        .setConstant(rtol * kAdjointAtolFactor * run.lambda_v_ref *
                     (lambda_z_per_v > 0 ? lambda_z_per_v : 1.0));
    b.peak = {};
    const bool ok = backward.solve(T0, rtol, atol);
    const IntegratorStats stats = backward.stats();
    result.backward_steps += stats.steps;
    result.backward_stats += stats;
    if (!ok) {
      result.error = fmt::format("the adjoint solve failed between t = {:.6g} and {:.6g} s ({})",
                                 T0, T1, backward.error());
      return false;
    }
    seen.x = std::max(seen.x, b.peak.x);
    seen.v = std::max(seen.v, b.peak.v);
    const bool loose = beyond(run.lambda_x_ref, seen.x) || beyond(run.lambda_v_ref, seen.v);
    if (!loose || attempt == 2 || !(seen.x > 0 && seen.v > 0)) break;
    run.lambda_refs_missed = true;
    run.lambda_x_ref = std::min(run.lambda_x_ref, seen.x);
    run.lambda_v_ref = std::min(run.lambda_v_ref, seen.v);
  }
  lambda = backward.lambda();
  dphi_dp += backward.quadrature();
  return true;
}

/// The states at the segment boundaries, in an unlinked temporary file: with
/// thousands of segments they would otherwise be the one part of the adjoint's
/// memory that grows with the simulated time (7 MB on the 720-tet cylinder at 30 s
/// in 0.05 s segments, against 11 MB for the whole forward run). In memory when no
/// temporary file can be made, and from the state on which the disk is full.
class BoundaryStates {
 public:
  /// States (x, v, z) of n values each.
  explicit BoundaryStates(long n) : n_(n), file_(std::tmpfile()) {}
  ~BoundaryStates() {
    if (file_) std::fclose(file_);
  }
  BoundaryStates(const BoundaryStates&) = delete;
  BoundaryStates& operator=(const BoundaryStates&) = delete;

  void push(const Eigen::VectorXd& x, const Eigen::VectorXd& v, const Eigen::VectorXd& z) {
    Eigen::VectorXd y(n_);
    y << x, v, z;
    // Flushed at once, so that a full disk shows here and not when reading back.
    if (file_ && memory_.empty() &&
        std::fseek(file_, static_cast<long>(in_file_ * n_ * sizeof(double)), SEEK_SET) == 0 &&
        std::fwrite(y.data(), sizeof(double), n_, file_) == static_cast<size_t>(n_) &&
        std::fflush(file_) == 0) {
      ++in_file_;
      return;
    }
    memory_.push_back(y);
  }

  void get(long k, long n, Eigen::VectorXd& x, Eigen::VectorXd& v, Eigen::VectorXd& z) {
    Eigen::VectorXd y(n_);
    if (k >= in_file_) {
      y = memory_[k - in_file_];
    } else if (std::fseek(file_, static_cast<long>(k * n_ * sizeof(double)), SEEK_SET) != 0 ||
               std::fread(y.data(), sizeof(double), n_, file_) != static_cast<size_t>(n_)) {
      throw IoError(fmt::format(
          "could not read segment boundary state {} back from the adjoint's temporary file ({})", k,
          std::strerror(errno)));
    }
    x = y.head(n);
    v = y.segment(n, n);
    z = y.tail(n_ - 2 * n);
  }

 private:
  long n_;
  std::FILE* file_;
  long in_file_ = 0;  // states 0 … in_file_ − 1 are in the file, the rest in memory
  std::vector<Eigen::VectorXd> memory_;
};

}  // namespace

void evaluate_adjoint(ExperimentRun& run, ExperimentResult& result) {
  const int n = run.n;
  const long budget = run.checkpoint_budget();
  if (run.planning()) {
    ExperimentResult plain;
    if (!run.plan_segments(plain)) {
      result = plain;
      return;
    }
  }
  const std::vector<double> T = run.boundaries();
  const int segments = static_cast<int>(T.size()) - 1;
  result.segments = segments;

  // Pass 1 (only with several segments): Φ and the state at every boundary but the
  // last, with the first step each restart takes (pass 2 retraces pass 1's steps).
  BoundaryStates boundaries(run.state_size());
  boundaries.push(run.x0, run.v0, run.z0);
  std::vector<long> segment_steps;
  std::vector<double> first_steps{0.0};
  result.phi_per_marker.setZero(run.objective.num_markers());
  if (!run.integrate_segments(T, segments - 1, result, [&](int, IdasIntegrator& integ) {
        boundaries.push(integ.positions(), integ.velocities(), integ.internal());
        segment_steps.push_back(integ.stats().steps);
        first_steps.push_back(integ.restart_step());
      }))
    return;

  Eigen::VectorXd dphi_dp = Eigen::VectorXd::Zero(run.map.size());
  Eigen::VectorXd lambda = Eigen::VectorXd::Zero(run.state_size());
  EvaluationPlan::AdjointPeaks seen;
  Eigen::VectorXd x, v, z;
  for (int k = segments - 1; k >= 0; --k) {
    boundaries.get(k, n, x, v, z);
    // Every segment is ONE IDAS checkpoint interval. With several, IDASolveB
    // re-integrates each interval from its checkpoint with a fresh Newton matrix;
    // that run can take more steps than the forward one did, and IDAS 6 then
    // stores Hermite points past the end of its array (a crash seen in long fits).
    // Pass 1 counted the steps of every segment but the last, whose count is
    // estimated from the others. A segment that still overruns is integrated again
    // with more room; in one interval it retraces pass 1's steps exactly, but the
    // overrunning run itself took other steps (creating an IDAS checkpoint changes
    // the stepping: 2047 instead of 2176 steps on test_gradients' bar), so the room
    // grows by a quarter over its count.
    long points = budget;
    if (segments == 1 && run.plan.planned_steps() > 0)
      points = std::min(budget, run.plan.planned_steps() * 5 / 4 + 8);
    else if (k + 1 < segments)
      points = segment_steps[k] + 8;
    else if (!segment_steps.empty())
      points = *std::max_element(segment_steps.begin(), segment_steps.end()) * 5 / 4 + 8;
    std::unique_ptr<IdasIntegrator> integ;
    // Steps of overrunning runs, counted in the statistics but not against a
    // trial's step limit: the run again retraces them (a line-search trial of the
    // bench bar failed in its retry at t = 1 s of 2 after a complete first run).
    long overrun = 0;
    bool ok = false;
    for (;;) {
      integ = run.start(T[k], x, v, z, first_steps[k]);
      integ->record_checkpoints(points);
      ok = run.advance(*integ, T[k + 1], result);
      const long steps = integ->stats().steps;
      if (!ok || steps < points) {
        result.forward_stats.steps += steps + overrun;
        break;
      }
      overrun += steps;
      points = std::max(points, steps) * 5 / 4 + 8;
    }
    if (!ok) return;
    if (segments == 1) run.plan.note_steps(integ->stats().steps);
    if (k == segments - 1) {
      run.add_quadratures(*integ, result);
      run.add_targets(T[k + 1], integ->positions(), result);
      run.set_adjoint_scale(result);
    }
    // A target at T[k+1] (a fixed time, so a boundary): λx(T⁻) = λx(T⁺) + ∂Φ_k/∂x.
    run.add_target_gradient(T[k + 1], integ->positions(), lambda.data());
    if (!backward_segment(run, *integ, T[k], T[k + 1], lambda, dphi_dp, seen, result)) return;
  }
  // The peaks are kept while they predict λ within kLooseTolerance, so that
  // evaluating one point twice gives one gradient.
  const auto off = [](double met, double ref) { return beyond(met, ref) || beyond(ref, met); };
  if (run.plan.adjoint_peaks().x == 0 || run.lambda_refs_missed || off(seen.x, run.lambda_x_ref) ||
      off(seen.v, run.lambda_v_ref))
    run.plan.note_adjoint_peaks({seen.x / run.misfit_rms, seen.v / run.misfit_rms});

  run.add_target_gradient(T[0], run.x0, lambda.data());
  if (run.static_initial()) {
    // + (λx + z₀,ₓᵀλz)(t₀)ᵀ x₀_q = −μᵀ ∂R/∂q at the static state, K₀ᵀ μ = λx + z₀,ₓᵀλz.
    run.factor_static_stiffness();
    Eigen::VectorXd rhs = lambda.head(n);
    if (lambda.size() > 2 * n)
      run.model.relaxed_internal_change_transpose(run.x, lambda.data() + 2 * n, rhs.data());
    const Eigen::VectorXd mu = run.K0->transpose().solve(rhs);
    if (!run.contract(mu.data(), -1.0, dphi_dp.data()))
      throw Error("an element is inadmissible at the static state");
  }
  result.gradient = dphi_dp;
  if (run.observation_count > 0)
    run.map.add_observation_gradient(result.dphi_dtheta, result.gradient);
  result.ok = true;
}

}  // namespace kelvin
