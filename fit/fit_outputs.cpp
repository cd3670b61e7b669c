#include "fit/fit_outputs.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>

#include "adjoint/marker_trajectory.hpp"
#include "adjoint/uncertainty.hpp"
#include "engine/output.hpp"
#include "fit/body_force_outputs.hpp"
#include "fit/fit_report.hpp"
#include "fit/fitted_scenario.hpp"

namespace kelvin {
namespace {

/// Standard errors are reported for maps small enough that JᵀJ is a few
/// forward-sensitivity runs; per-element fields are left to the L-curve.
constexpr int kMaxUncertaintyParameters = 50;
/// Worst and best markers plotted in the report.
constexpr int kWorstTracks = 2, kBestTracks = 1;

Eigen::VectorXd model_values(const ParameterMap& map, const Eigen::VectorXd& p) {
  Eigen::VectorXd q(map.size());
  for (int j = 0; j < map.size(); ++j) q[j] = map.value(p, j);
  return q;
}

/// RMS distances at p: overall, per marker and per shape target of every
/// experiment (experiment order, then the objective's), NaN where a run failed.
struct RmsAt {
  double overall = 0;
  std::vector<double> markers, targets;
};

RmsAt rms_at(FitProblem& problem, const Eigen::VectorXd& p, const std::atomic<bool>* interrupt) {
  GradientOptions o;
  o.method = GradientMethod::kNone;
  o.interrupt = interrupt;
  const Evaluation ev = problem.evaluate(p, o);
  constexpr double nan = std::numeric_limits<double>::quiet_NaN();
  RmsAt out;
  for (int k = 0; k < problem.num_experiments(); ++k) {
    const Experiment& ex = problem.experiment(k);
    const ExperimentResult& r = ev.experiments[k];
    const Eigen::VectorXd rms = r.ok ? ex.objective().marker_rms(r.phi_per_marker)
                                     : Eigen::VectorXd::Constant(ex.objective().num_markers(), nan);
    out.markers.insert(out.markers.end(), rms.data(), rms.data() + rms.size());
    for (size_t t = 0; t < ex.targets().size(); ++t)
      out.targets.push_back(r.ok ? ex.targets()[t].rms(r.phi_targets[static_cast<long>(t)]) : nan);
  }
  out.overall = ev.ok ? ev.rms : nan;
  return out;
}

/// Simulated markers of experiment k over its frames in the objective window, at the
/// start (false) or the fitted point (true): each run serves every plotted marker of
/// the experiment (the bundled example's three plots had taken six runs).
using PlotRuns = std::map<std::pair<int, bool>, MarkerTrajectory>;

/// Observed frames of `marker` inside the objective window, and the simulated
/// positions there with the start and the fitted parameters.
bool track_plot(FitProblem& problem, int k, const std::string& marker, const FitSummary& s,
                const std::atomic<bool>* interrupt, PlotRuns& runs, TrackPlot& plot) {
  Experiment& ex = problem.experiment(k);
  const MarkerTracks& tracks = ex.scenario().markers.observed;
  const auto& embedded = ex.scenario().markers.embedded;
  const auto col =
      std::find(tracks.names.begin(), tracks.names.end(), marker) - tracks.names.begin();
  int sim = -1;
  for (int i = 0; i < static_cast<int>(embedded.size()); ++i)
    if (embedded[i].name == marker) sim = i;
  if (sim < 0 || col == static_cast<long>(tracks.names.size())) return false;
  std::vector<int> frames;
  for (int f = 0; f < static_cast<int>(tracks.times.size()); ++f) {
    const double t = tracks.times[f];
    if (t >= ex.objective().window_begin() && t <= ex.objective().window_end()) frames.push_back(f);
  }
  if (frames.empty()) return false;
  for (int f : frames) plot.t.push_back(tracks.times[f]);
  const auto run = [&](bool fitted) -> const MarkerTrajectory& {
    auto [at, fresh] = runs.try_emplace({k, fitted});
    if (fresh)
      at->second =
          simulate_markers(problem, k, fitted ? s.best : s.start, plot.t, false, interrupt);
    return at->second;
  };
  const MarkerTrajectory& before = run(false);
  const MarkerTrajectory& after = run(true);
  if (!before.ok || !after.ok) return false;
  const int m = static_cast<int>(frames.size());
  plot.experiment = ex.scenario().name;
  plot.marker = marker;
  plot.observed.resize(3, m);
  plot.before.resize(3, m);
  plot.after.resize(3, m);
  for (int j = 0; j < m; ++j) {
    plot.observed.col(j) = tracks.xyz.block<3, 1>(3 * col, frames[j]);
    plot.before.col(j) = before.positions[j].col(sim);
    plot.after.col(j) = after.positions[j].col(sim);
  }
  return true;
}

void write_marker_rms_csv(const std::string& path, const std::vector<MarkerRms>& rows) {
  std::string text = "experiment,marker,rms_before_mm,rms_after_mm\n";
  for (const auto& r : rows)
    text +=
        fmt::format("{},{},{:.6g},{:.6g}\n", r.experiment, r.marker, r.before * 1e3, r.after * 1e3);
  write_file_atomic(path, text);
}

/// One VTU of the fitted (and starting) parameter fields when any block varies
/// over the body; returns its file name, or "" when every block is global.
std::string write_parameter_fields(FitProblem& problem, const FitSummary& s) {
  const ParameterMap& map = problem.map();
  bool varies = false;
  for (const auto& b : map.blocks()) varies |= b.count > 1 && !b.slot.is_force();
  if (!varies) return "";
  const Mesh& mesh = problem.mesh();
  std::vector<std::pair<std::string, Eigen::VectorXd>> fields;
  for (int k = 0; k < static_cast<int>(map.blocks().size()); ++k) {
    const ParameterBlock& b = map.blocks()[k];
    if (b.slot.is_force()) continue;  // write_body_force's series
    Eigen::VectorXd fitted(mesh.num_tets()), start(mesh.num_tets());
    for (int e = 0; e < mesh.num_tets(); ++e) {
      const bool mapped = b.entry[e] >= 0;
      fitted[e] =
          mapped ? map.element_value(s.best, k, e) : std::numeric_limits<double>::quiet_NaN();
      start[e] =
          mapped ? map.element_value(s.start, k, e) : std::numeric_limits<double>::quiet_NaN();
    }
    fields.emplace_back(b.target, fitted);
    fields.emplace_back(b.target + "_start", start);
    fields.emplace_back(b.target + "_ratio", fitted.cwiseQuotient(start));
  }
  VtuSeries vtu(s.outdir, "parameters", mesh);
  vtu.write_frame(0, mesh.nodes, Eigen::Matrix3Xd::Zero(3, mesh.num_nodes()), fields);
  return "parameters.pvd";
}

}  // namespace

std::string write_fit_outputs(FitProblem& problem, const FitSummary& s,
                              const std::atomic<bool>* interrupt) {
  const ParameterMap& map = problem.map();
  FitReportData data;
  const Scenario& scenario = problem.scenario();
  data.title = scenario.name;
  data.scenario_path = scenario.path;
  data.algorithm = s.algorithm;
  data.gradient_method = s.gradient_method;
  data.stop_reason = s.stop_reason;
  data.evaluations = s.evaluations;
  data.failures = s.failures;
  data.seconds = s.seconds;
  data.interrupted = s.interrupted;
  for (int j = 0; j < map.size(); ++j) data.labels.push_back(map.label(j));
  data.initial = model_values(map, s.start);
  data.fitted = model_values(map, s.best);
  data.lower = map.lower();
  data.upper = map.upper();
  for (int j = 0; j < map.size(); ++j)
    if (map.is_log(j)) {
      data.lower[j] = std::exp(data.lower[j]);
      data.upper[j] = std::exp(data.upper[j]);
    }
  data.history = s.history;
  data.lcurve = s.lcurve;

  // fitted.yaml first: it is what the user came for, and needs no simulation.
  FemModel& model = problem.model();
  map.apply(s.best, model);
  write_fitted_scenario(scenario, map, model, s.outdir, s.best);
  data.files.push_back("fitted.yaml");
  data.files.push_back("history.csv");
  data.files.push_back("fit-state.yaml");
  if (const std::string vtu = write_parameter_fields(problem, s); !vtu.empty())
    data.files.push_back(vtu);
  for (const std::string& f : write_body_force(model, s.outdir)) data.files.push_back(f);

  const bool stopped = s.interrupted || (interrupt && interrupt->load());
  if (!stopped) {
    const RmsAt before = rms_at(problem, s.start, interrupt);
    const RmsAt after = rms_at(problem, s.best, interrupt);
    data.rms_before = before.overall;
    data.rms_after = after.overall;
    std::vector<std::pair<int, std::string>> where;  // (experiment, marker) per row
    for (int k = 0; k < problem.num_experiments(); ++k) {
      const Experiment& ex = problem.experiment(k);
      for (const auto& name : ex.objective().names()) {
        data.markers.push_back(
            {ex.scenario().name, name, before.markers[where.size()], after.markers[where.size()]});
        where.emplace_back(k, name);
      }
      for (const ShapeTarget& t : ex.targets()) {
        const size_t i = data.targets.size();
        data.targets.push_back({ex.scenario().name, t.name(), t.time(), t.coordinates(),
                                before.targets[i], after.targets[i]});
      }
    }
    if (!data.markers.empty()) {
      write_marker_rms_csv((std::filesystem::path(s.outdir) / "marker-rms.csv").string(),
                           data.markers);
      data.files.push_back("marker-rms.csv");
    }

    std::vector<int> order(data.markers.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
    std::sort(order.begin(), order.end(),
              [&](int a, int b) { return data.markers[a].after > data.markers[b].after; });
    std::vector<int> chosen;
    for (int i = 0; i < std::min<int>(kWorstTracks, order.size()); ++i) chosen.push_back(order[i]);
    for (int i = 0; i<kBestTracks&& static_cast<int>(order.size())> kWorstTracks + i; ++i)
      chosen.push_back(order[order.size() - 1 - i]);
    PlotRuns runs;
    for (int i : chosen) {
      TrackPlot plot;
      if (track_plot(problem, where[i].first, where[i].second, s, interrupt, runs, plot)) {
        plot.rms_before = data.markers[i].before;
        plot.rms_after = data.markers[i].after;
        data.tracks.push_back(std::move(plot));
      }
    }

    if (map.size() <= kMaxUncertaintyParameters) {
      // The fit's last Gauss–Newton restart often began at the final best point: its
      // sensitivity solve (the cost of the whole report on the benchmark bar) is not
      // repeated.
      const ParameterUncertainty u = s.uncertainty.holds(s.best)
                                         ? s.uncertainty.value
                                         : gauss_newton_uncertainty(problem, s.best, interrupt);
      if (u.ok) {
        data.std_error = u.std_error;
        data.noise_sigma = u.sigma;
      } else {
        data.extra_sections.push_back(
            fmt::format("## Standard errors\n\nNot computed: {}\n", u.error));
      }
    }
  }
  if (!s.lcurve.empty()) {
    std::string text = "gamma,misfit,roughness,rms_mm,evaluations\n";
    for (const auto& point : s.lcurve)
      text += fmt::format("{:.6g},{:.9g},{:.9g},{:.6g},{}\n", point.gamma, point.misfit,
                          point.roughness, point.rms * 1e3, point.evaluations);
    write_file_atomic((std::filesystem::path(s.outdir) / "lcurve.csv").string(), text);
    data.files.push_back("lcurve.csv");
  }
  return write_fit_report(s.outdir, data);
}

}  // namespace kelvin
