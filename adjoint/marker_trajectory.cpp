#include "adjoint/marker_trajectory.hpp"

#include <fmt/format.h>
#include <idas/idas.h>
#include <nvector/nvector_serial.h>

#include <memory>
#include <type_traits>

#include "adjoint/experiment_run.hpp"
#include "engine/error.hpp"
#include "engine/markers.hpp"

namespace kelvin {
namespace {

struct VectorDeleter {
  void operator()(N_Vector v) const { N_VDestroy(v); }
};
using Vector = std::unique_ptr<std::remove_pointer_t<N_Vector>, VectorDeleter>;

/// d x*/dp (3·markers × np) from position sensitivities over the free dofs
/// (n × np): clamped nodes follow a prescribed motion and contribute nothing.
Eigen::MatrixXd marker_sensitivities(const FemModel& model,
                                     const std::vector<MarkerEmbedding>& markers,
                                     const Eigen::MatrixXd& sx) {
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(3 * markers.size(), sx.cols());
  for (size_t i = 0; i < markers.size(); ++i)
    for (int a = 0; a < 4; ++a) {
      const int node = model.mesh().tets(a, markers[i].tet);
      for (int c = 0; c < 3; ++c)
        if (const int d = model.dof(node, c); d >= 0)
          out.row(3 * i + c) += markers[i].weights[a] * sx.row(d);
    }
  return out;
}

}  // namespace

MarkerTrajectory simulate_markers(Experiment& experiment, const ParameterMap& map,
                                  const Eigen::VectorXd& p, const std::vector<double>& times,
                                  bool with_sensitivities, const std::atomic<bool>* interrupt) {
  MarkerTrajectory out;
  const Scenario& scenario = experiment.scenario();
  const auto& markers = scenario.markers.embedded;
  FemModel& model = experiment.model();
  GradientOptions options;
  options.method = with_sensitivities ? GradientMethod::kForward : GradientMethod::kNone;
  options.interrupt = interrupt;
  map.apply(p, model);
  try {
    ExperimentRun run(experiment, map, p, options);
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
    auto integ = run.start(run.t0, run.x0, run.v0);
    Eigen::MatrixXd yS0;
    // The sensitivities here build JᵀJ (standard errors, the fit's Gauss–Newton
    // restart), whose singular values they give to two digits either way: with
    // error control the bench bar's solve took 20.6k steps and 12.1 s at its fitted
    // point, without it 9.9k steps (the plain run's 9.9k) and 6.2 s.
    if (with_sensitivities) yS0 = run.add_sensitivities(*integ, false);
    const int n = run.n, np = map.size();
    Vector sensitivity(N_VNew_Serial(2 * n, static_cast<SUNContext>(integ->sundials_context())));
    Eigen::MatrixXd sx(n, np);
    Eigen::Matrix3Xd x, v;
    ExperimentResult progress;
    for (double t : times) {
      if (!run.advance(*integ, t, progress, run.t_end)) {
        out.error = progress.error;
        return out;
      }
      model.expand(t, integ->positions().data(), integ->velocities().data(), x, v);
      out.times.push_back(t);
      out.positions.push_back(marker_positions(model.mesh(), markers, x));
      if (!with_sensitivities) continue;
      if (t == run.t0) {
        // Before the first step IDAS has no interpolant to ask.
        sx = yS0.topRows(n);
      } else {
        for (int j = 0; j < np; ++j) {
          if (IDAGetSensDky1(integ->idas_memory(), t, 0, j, sensitivity.get()) < 0)
            throw Error(fmt::format("could not interpolate the sensitivities at t = {:.6g} s", t));
          sx.col(j) = Eigen::Map<const Eigen::VectorXd>(N_VGetArrayPointer(sensitivity.get()), n);
        }
      }
      out.sensitivities.push_back(marker_sensitivities(model, markers, sx));
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
