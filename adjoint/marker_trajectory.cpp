#include "adjoint/marker_trajectory.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "adjoint/experiment_run.hpp"
#include "base/error.hpp"
#include "engine/markers.hpp"

namespace kelvin {
namespace {

/// dr/dp ((3·objective markers) × np) of the samples at capture time t, from position
/// sensitivities over the free dofs (n × np) at the model time compared with it:
/// clamped nodes follow a prescribed motion and contribute nothing; observation
/// entries from the objective's own derivatives.
Eigen::MatrixXd residual_sensitivities(const FemModel& model, const MarkerObjective& objective,
                                       const ParameterMap& map, double t, bool clock_moves,
                                       const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v,
                                       const Eigen::MatrixXd& sx) {
  const int nm = objective.num_markers();
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(3 * nm, sx.cols());
  for (int i = 0; i < nm; ++i) {
    const Eigen::Vector4d w = objective.weights(i, model);
    for (int a = 0; a < 4; ++a) {
      const int node = model.mesh().tets(a, objective.tet(i));
      for (int c = 0; c < 3; ++c)
        if (const int d = model.dof(node, c); d >= 0) out.row(3 * i + c) += w[a] * sx.row(d);
    }
    if (map.observation_blocks().empty()) continue;
    const Eigen::Matrix3Xd J = objective.sample_jacobian(i, t, model, x, v, clock_moves);
    for (const auto& o : map.observation_blocks())
      out.block(3 * i, o.offset, 3, o.count) = J.middleCols(o.theta, o.count);
  }
  return out;
}

}  // namespace

MarkerTrajectory simulate_markers(FitProblem& problem, int index, const Eigen::VectorXd& p,
                                  const std::vector<double>& times, bool with_sensitivities,
                                  const std::atomic<bool>* interrupt,
                                  const std::vector<int>* sensitivity_entries) {
  MarkerTrajectory out;
  Experiment& experiment = problem.experiment(index);
  const ParameterMap& map = problem.map();
  const Scenario& scenario = experiment.scenario();
  const auto& markers = scenario.markers.embedded;
  FemModel& model = experiment.model();
  GradientOptions options;
  options.method = with_sensitivities ? GradientMethod::kForward : GradientMethod::kNone;
  options.interrupt = interrupt;
  options.sensitivity_entries = sensitivity_entries;
  experiment.apply(map, p);
  const MarkerObjective& objective = experiment.objective();
  try {
    ExperimentRun run(experiment, problem.plan(index), map, p, options);
    for (size_t k = 0; k < times.size(); ++k)
      if (times[k] < run.t0 || times[k] > run.t_end || (k > 0 && times[k] < times[k - 1])) {
        out.error = fmt::format(
            "marker sample times must be ascending within the run [{:g}, {:g}] s; got t = {:.9g} "
            "s",
            run.t0, run.t_end, times[k]);
        return out;
      }

    // Built like Experiment::evaluate's forward pass and stopped only at the end of
    // the run, so that the samples lie on the very trajectory whose Φ a fit sees.
    auto integ = run.start(run.t0, run.x0, run.v0, run.z0);
    Eigen::MatrixXd yS0;
    // The sensitivities here build JᵀJ (standard errors, the fit's Gauss–Newton
    // restart), whose singular values they give to two digits either way: with
    // error control the bench bar's solve took 20.6k steps and 12.1 s at its fitted
    // point, without it 9.9k steps (the plain run's 9.9k) and 6.2 s.
    if (with_sensitivities) yS0 = run.add_sensitivities(*integ, false);
    const int n = run.n, np = map.size();
    const std::vector<int> entries = run.sensitivity_entries();
    Eigen::MatrixXd sx = Eigen::MatrixXd::Zero(n, np);
    Eigen::Matrix3Xd x, v;
    ExperimentResult progress;
    for (double t : times) {
      // The capture at t is compared with the model at t − τ, held at the run's ends.
      const double tm = std::clamp(objective.model_time(t), run.t0, run.t_end);
      if (!run.advance(*integ, tm, progress, run.t_end)) {
        out.error = progress.error;
        return out;
      }
      model.expand(tm, integ->positions().data(), integ->velocities().data(), x, v);
      out.times.push_back(t);
      out.positions.push_back(marker_positions(model.mesh(), markers, x));
      Eigen::Matrix3Xd r(3, objective.num_markers());
      Eigen::Vector3d xs, xo;
      for (int i = 0; i < objective.num_markers(); ++i)
        r.col(i) = objective.sample_pair(i, t, model, x, xs, xo) ? Eigen::Vector3d(xs - xo)
                                                                 : Eigen::Vector3d::Constant(NAN);
      out.residuals.push_back(r);
      if (!with_sensitivities) continue;
      // Before the first step IDAS has no interpolant to ask.
      const Eigen::MatrixXd s = tm == run.t0 ? yS0 : integ->state_sensitivities();
      for (size_t j = 0; j < entries.size(); ++j)
        sx.col(entries[j]) = s.col(static_cast<long>(j)).head(n);
      out.residual_sensitivities.push_back(residual_sensitivities(
          model, objective, map, t, tm == objective.model_time(t), x, v, sx));
    }
    out.stats = integ->stats();
  } catch (const Error& e) {
    // As in Experiment::evaluate: inadmissible parameters fail this run only.
    out.error = e.what();
    return out;
  }
  out.ok = true;
  return out;
}

}  // namespace kelvin
