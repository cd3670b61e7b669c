#include "diagnose/diagnosis.hpp"

#include <fmt/format.h>

#include <Eigen/QR>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <sstream>

#include "adjoint/fit_problem.hpp"
#include "adjoint/uncertainty.hpp"
#include "base/error.hpp"
#include "base/spread_tasks.hpp"
#include "diagnose/diagnosis_exchange.hpp"
#include "diagnose/diagnosis_model.hpp"
#include "diagnose/extended_scenario.hpp"
#include "diagnose/heldout_prediction.hpp"
#include "diagnose/learned_correction.hpp"
#include "engine/output.hpp"
#include "fit/fit_loop.hpp"
#include "fit/fitted_scenario.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

MisfitFigures misfit(FitProblem& problem, const Eigen::VectorXd& p,
                     const std::atomic<bool>* interrupt) {
  MisfitFigures f;
  const GaussNewtonSystem g = gauss_newton_system(problem, p, interrupt, false);
  if (!g.ok) {
    f.error = g.error;
    return f;
  }
  f.ok = true;
  f.residual = g.residual;
  f.entries = g.samples;
  f.samples = static_cast<int>(g.residual.size());
  f.sum_sq = g.residual.squaredNorm();
  f.rms = f.samples ? std::sqrt(f.sum_sq / f.samples) : 0;
  return f;
}

std::vector<std::string> labels_of(const ParameterMap& map) {
  std::vector<std::string> labels;
  for (int j = 0; j < map.size(); ++j) labels.push_back(map.label(j));
  return labels;
}

/// Saved parameters of a finished fit: `label,value` lines (optimiser space).
void save_parameters(const std::string& path, const std::vector<std::string>& labels,
                     const Eigen::VectorXd& p) {
  std::string csv = "label,value\n";
  for (std::size_t j = 0; j < labels.size(); ++j)
    csv += fmt::format("{},{:.17g}\n", labels[j], p[static_cast<long>(j)]);
  write_file_atomic(path, csv);
}

/// Collective: `write()` on rank 0 alone, its value on every rank; its failure ends
/// every rank with its message (no rank may go on to wait for one that stopped) as a
/// failed run, not an input error.
std::string on_root(const std::function<std::string()>& write) {
  Communicator& comm = world();
  ByteWriter out;
  if (comm.root()) {
    std::string value, error;
    try {
      value = write();
    } catch (const std::exception& e) {
      error = e.what();
    }
    out.put(error);
    out.put(value);
  }
  const std::vector<std::string> all = comm.all_gather(out.bytes());
  ByteReader in(all[0]);
  std::string error, value;
  in.get(error);
  in.get(value);
  if (!error.empty()) throw std::runtime_error(error);
  return value;
}

/// A state file's text ("" when there is none).
std::string read_state(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream text;
  if (in) text << in.rdbuf();
  return text.str();
}

/// The parameters a state file's text holds when they are for this map, else empty.
Eigen::VectorXd saved_parameters(const std::string& text, const ParameterMap& map) {
  std::istringstream in(text);
  std::string line;
  std::getline(in, line);
  Eigen::VectorXd p(map.size());
  int j = 0;
  while (std::getline(in, line)) {
    const auto comma = line.rfind(',');
    if (comma == std::string::npos || j >= map.size() || line.substr(0, comma) != map.label(j))
      return {};
    try {
      p[j++] = std::stod(line.substr(comma + 1));
    } catch (const std::exception&) {
      return {};
    }
  }
  if (j != map.size() || !p.allFinite()) return {};
  return p;
}

struct FitRun {
  Eigen::VectorXd p;
  int evaluations = 0;
  bool ok = false, resumed = false;
  bool finished = false;  // ran to its end now: its parameters are to be saved
  std::string error;
};

/// Fits m from p0, or takes the parameters `saved` (the text of the state file
/// `state` a finished fit left, "" when none) on --resume; progress lines go through
/// `say`.
FitRun fit_model(Model& m, const Eigen::VectorXd& p0, const std::string& state,
                 const std::string& saved, const DiagnoseOptions& o, const ProgressLine& say,
                 const std::string& label, double ftol_rel, int max_evaluations = 0) {
  FitRun run;
  const ParameterMap& map = m.problem->map();
  if (o.resume) {
    run.p = saved_parameters(saved, map);
    if (run.p.size() == map.size()) {
      run.ok = run.resumed = true;
      if (say) say(fmt::format("  {}: resumed from {}", label, state));
      return run;
    }
  }
  FitOptions f = fit_options_of(*m.scenario);
  f.gradient.interrupt = o.interrupt;
  f.ftol_rel = std::max(f.ftol_rel, ftol_rel);
  f.precision = ftol_rel;
  // Its nominal parameters absorbed what the model lacks, so a fit starts in a valley
  // where they and the effect trade off; one sensitivity solve at the start scales it.
  f.gauss_newton_start = map.size() <= kGaussNewtonStartParameters;
  if (max_evaluations > 0) f.max_evaluations = max_evaluations;
  if (o.max_evaluations > 0) f.max_evaluations = o.max_evaluations;
  f.on_progress = [&](const std::string& line) {
    if (say) say(fmt::format("  {}: {}", label, line));
  };
  // Every trial, so that the time a refit spends on rejected line-search trials or
  // failed simulations is seen where it is spent.
  f.on_evaluation = [&](const FitRecord& r) {
    if (!say) return;
    const std::string what = r.accepted ? fmt::format("rms {:8.4f} mm", r.rms * 1e3)
                             : r.ok     ? fmt::format("rms {:8.4f} mm (not better)", r.rms * 1e3)
                                        : "failed: " + r.error;
    say(fmt::format("  {}: eval {:3d}  {}  {:7.1f} s", label, r.evaluation, what, r.seconds));
  };
  const FitOutcome out = run_fit(*m.problem, p0, f);
  run.evaluations = out.evaluations;
  if (say) say(fmt::format("  {}: {} evaluations; {}", label, out.evaluations, out.stop_reason));
  if (!out.best.evaluation) {
    run.error = out.history.empty() ? out.stop_reason : out.history.back().error;
    return run;
  }
  run.p = out.p;
  run.ok = true;
  run.finished = !out.interrupted;
  return run;
}

std::vector<NamedValue> named_values(const ParameterMap& map, const Eigen::VectorXd& p,
                                     const std::vector<int>& entries,
                                     const ParameterUncertainty* u = nullptr) {
  std::vector<NamedValue> out;
  for (int j : entries) {
    NamedValue v;
    v.name = map.label(j);
    v.value = map.value(p, j);
    if (u && u->ok) v.std_error = u->std_error[j];
    out.push_back(v);
  }
  return out;
}

/// u, or when an entry the data cannot place (V07's and V09's λ, driven to 0.01 Pa)
/// or one that moves no marker made JᵀJ singular while the others' is regular, the
/// others' errors with those held, `error` naming them.
ParameterUncertainty with_held_errors(ParameterUncertainty u, const ParameterMap& map,
                                      const Eigen::VectorXd& p) {
  if (u.ok || !u.resolved_regular || u.root_inverse.rows() == 0) return u;
  u.std_error = standard_errors_with_unresolved_held(u, map, p);
  std::string held;
  for (long j = 0; j < u.std_error.size(); ++j)
    if (!std::isfinite(u.std_error[j])) held += (held.empty() ? "" : ", ") + map.label(j);
  u.ok = true;
  u.error = fmt::format("errors given {} held (JᵀJ is singular with it: {})", held, u.error);
  return u;
}

std::vector<int> range(int n) {
  std::vector<int> v(n);
  for (int k = 0; k < n; ++k) v[k] = k;
  return v;
}

/// A refit's start from the screening's Gauss–Newton step: the base parameters
/// `base_p` (leading the refit model's map) moved by the step of the fitted entries
/// that compensated for the effect's absence (a clock lag fitted as viscosity), and
/// the candidate's own entries `entries` by its step. `group` is its entries in the
/// screening model; a candidate screened as alternatives (score of the chosen one)
/// puts its step on its refit's modulus, entries[0].
Eigen::VectorXd start_from_score(const ParameterMap& map, const Eigen::VectorXd& base_p,
                                 const CandidateScore& score, bool alternatives,
                                 const std::vector<int>& group, const std::vector<int>& entries) {
  Eigen::VectorXd p0 = map.initial();
  const long n = base_p.size();
  p0.head(n) = base_p;
  if (score.fitted_step.size() == n) p0.head(n) += score.fitted_step;
  if (alternatives) {
    if (score.step.size() == 1 && !entries.empty()) p0[entries[0]] += score.step[0];
  } else if (entries.size() == group.size()) {
    for (std::size_t a = 0; a < score.active.size(); ++a) {
      const long k = std::find(group.begin(), group.end(), score.active[a]) - group.begin();
      if (k < static_cast<long>(entries.size())) p0[entries[k]] += score.step[a];
    }
  }
  return p0;
}

/// For a candidate screened as alternatives (the anisotropy's directions, the
/// relaxation's times): the score of the one alone that explains most, its index
/// put in `choice` (its refit's form).
CandidateScore chosen_alternative(const GaussNewtonSystem& g, int n_fitted,
                                  const std::vector<int>& group, const ScreeningOptions& so,
                                  const ParameterMap& map, int& choice) {
  std::vector<std::pair<std::string, std::vector<int>>> single;
  for (int j : group) single.push_back({map.label(j), {j}});
  const auto s = score_candidates(g.residual, g.jacobian, range(n_fitted), single, so);
  int best = 0;
  for (std::size_t k = 1; k < s.size(); ++k)
    if (s[k].predicted_drop > s[best].predicted_drop) best = static_cast<int>(k);
  choice = best;
  return s[best];
}

/// Standard normal upper quantile z with P(Z > z) = p, from the χ²(1) quantile.
double normal_quantile(double p) {
  return std::sqrt(chi_square_quantile(2 * p, 1));
}

/// Where a fitted field of the refit differs most from the nominal material: the
/// part of the body (by distance from the clamp) where |ln(q / q₀)| exceeds half its
/// largest value, q the density or the first elastic modulus.
std::string field_region(const Model& m, const Eigen::VectorXd& p, const Scenario& nominal,
                         bool density, const BodyAxis& axis) {
  FemModel& model = m.problem->experiment(0).model();
  m.problem->map().apply(p, model);
  const Mesh& mesh = model.mesh();
  constexpr int kBins = 20;
  std::vector<double> sum(kBins, 0);
  std::vector<int> count(kBins, 0);
  const double q0 = density ? nominal.material.density
                    : nominal.material.elastic[0].params.count("mu")
                        ? nominal.material.elastic[0].params.at("mu")
                        : nominal.material.elastic[0].params.begin()->second;
  const int index = [&] {
    if (density) return 0;
    const auto& params = model.terms()[0].model->params();
    for (std::size_t k = 0; k < params.size(); ++k)
      if (params[k].name == "mu") return static_cast<int>(k);
    return 0;
  }();
  for (int e = 0; e < mesh.num_tets(); ++e) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int a = 0; a < 4; ++a) c += 0.25 * mesh.nodes.col(mesh.tets(a, e));
    const int b = std::clamp(static_cast<int>(axis.along(c) * kBins), 0, kBins - 1);
    const double q = density ? model.density()[e] : model.terms()[0].q(index, e);
    sum[b] += std::log(q / q0);
    ++count[b];
  }
  double big = 0;
  for (int b = 0; b < kBins; ++b)
    if (count[b]) big = std::max(big, std::abs(sum[b] / count[b]));
  double u0 = 1, u1 = 0;
  for (int b = 0; b < kBins; ++b)
    if (count[b] && std::abs(sum[b] / count[b]) > 0.5 * big) {
      u0 = std::min(u0, double(b) / kBins);
      u1 = std::max(u1, double(b + 1) / kBins);
    }
  if (u1 <= 0.25) return "clamp zone";
  if (u0 >= 0.75) return "free end";
  if (u1 <= 0.6) return "clamp half";
  if (u0 >= 0.4) return "free half";
  return "whole body";
}

std::string describe(const MissingForce& f) {
  if (!f.ok) return "not found: " + f.error;
  if (f.where.empty())
    return fmt::format(
        "rms {:.4f} mm: no field fitted at the first stage's tolerances does better at the "
        "scenario's, so none is kept (noise alone would reach LR {:.1f})",
        f.rms_before * 1e3, f.threshold);
  std::string shares;
  for (const auto& r : f.regions)
    shares += fmt::format("{}{} {:.0f} %", shares.empty() ? "" : ", ", r.name, 100 * r.share);
  return fmt::format(
      "rms {:.4f} → {:.4f} mm (LR {:.1f}; noise alone stays below {:.1f}); most in the {} "
      "({}), peak at {:.3g} s",
      f.rms_before * 1e3, f.rms_after * 1e3, f.statistic, f.threshold, f.where, shares,
      f.peak_time);
}

std::string slug(const Candidate& c) {
  std::string s = c.id;
  if (!c.where.empty() && c.id == "marker_offset") s += "-" + c.where;
  return s;
}

/// Fills d.predicted_heldout_drop for the candidates of `order` that clear their
/// threshold: summed over the held-out motions, from each motion's sensitivity solve
/// of the screening model at the nominal fit; a probed candidate (its linearised step
/// is blind to it) from one held-out run at its probe instead. All NaN when a held-out
/// solve fails.
void predict_heldout_drops(Diagnosis& d, const std::vector<int>& order,
                           const std::map<int, CandidateScore>& marginal,
                           const std::map<int, double>& threshold,
                           const std::map<int, Eigen::VectorXd>& probe_start,
                           const std::vector<const Candidate*>& all, const ParameterMap& smap,
                           const Eigen::VectorXd& p_screen, int n_nominal, const Scenario& nominal,
                           const fs::path& models, const DiagnoseOptions& o,
                           ScreeningCosts& costs) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<int> passed;
  for (int c : order)
    if (marginal.at(c).error.empty() && marginal.at(c).statistic > threshold.at(c))
      passed.push_back(c);
  for (int c : passed) d.predicted_heldout_drop[c] = 0;
  const auto fail = [&](const std::string& why) {
    if (o.progress) o.progress("  held-out prediction not made: " + why);
    std::fill(d.predicted_heldout_drop.begin(), d.predicted_heldout_drop.end(), nan);
  };
  for (std::size_t k = 0; k < d.settings.validate.size(); ++k) {
    if (any_interrupted(world(), o.interrupt && o.interrupt->load())) return fail("interrupted");
    const std::string& path = d.settings.validate[k];
    Model h = load_model(path, nominal, all, true,
                         (models / fmt::format("heldout{}-screening.yaml", k)).string());
    const ParameterMap& hmap = h.problem->map();
    bool same = hmap.size() == smap.size();
    for (int j = 0; same && j < smap.size(); ++j) same = hmap.label(j) == smap.label(j);
    if (!same) return fail(path + ": its candidates' parameters differ from the training's");
    const GaussNewtonSystem g = screening_system(h, path, nominal, all, -1, p_screen, models,
                                                 fmt::format("heldout{}-screening", k), o.interrupt,
                                                 world(), nullptr, &costs);
    if (!g.ok) return fail(path + ": " + g.error);
    const std::vector<int> fitted = range(n_nominal);
    for (int c : passed) {
      double drop = predicted_heldout_drop(g.residual, g.jacobian, marginal.at(c), fitted);
      if (probe_start.count(c)) {
        const Candidate& cand = d.candidates[c];
        Model hp =
            load_model(path, nominal, {&cand}, false,
                       (models / fmt::format("heldout{}-{}-probe.yaml", k, slug(cand))).string());
        const MisfitFigures f = misfit(*hp.problem, probe_start.at(c), o.interrupt);
        drop = f.ok && f.samples == d.nominal_heldout[k].before.samples
                   ? d.nominal_heldout[k].before.sum_sq - f.sum_sq
                   : nan;
      }
      d.predicted_heldout_drop[c] += drop;
    }
  }
  if (o.progress)
    for (int c : passed)
      o.progress(fmt::format("  {:<22} predicted held-out ‖h‖² drop {:.4g} mm²", slug(*all[c]),
                             d.predicted_heldout_drop[c] * 1e6));
}

/// A candidate of the user's must make a scenario kelvin accepts, and be nested: at its
/// entries' start values its model must put the tracks where the nominal model does
/// (within what noise could explain at level `alpha`), or every score and refit
/// measured against the nominal fit would be wrong. Errors name its entry.
void check_custom_candidate(const Candidate& cand, const Scenario& nominal, FitProblem& base,
                            const Eigen::VectorXd& p, double alpha, const fs::path& models,
                            const DiagnoseOptions& o) {
  Model model;
  try {
    model =
        load_model(nominal.path, nominal, {&cand}, false, (models / (cand.id + ".yaml")).string());
  } catch (const Error& e) {
    throw Error(fmt::format("{}: its extended model ({}) is refused: {}", cand.origin,
                            (models / (cand.id + ".yaml")).string(), e.what()));
  }
  const ParameterMap& map = model.problem->map();
  Eigen::VectorXd q = map.initial();
  q.head(p.size()) = p;
  const MisfitFigures before = misfit(base, p, o.interrupt),
                      after = misfit(*model.problem, q, o.interrupt);
  if (!before.ok) throw Error(fmt::format("the nominal model does not run: {}", before.error));
  if (!after.ok)
    throw Error(fmt::format("{}: its model does not run at its start values: {}", cand.origin,
                            after.error));
  if (after.residual.size() != before.residual.size())
    throw Error(fmt::format("{}: its model sees other samples than the nominal's", cand.origin));
  const double sigma = estimate_noise(before.residual, before.entries).sigma;
  const double moved = (after.residual - before.residual).squaredNorm() / (sigma * sigma),
               threshold = chi_square_quantile(alpha, 1);
  if (o.progress)
    o.progress(
        fmt::format("  {}: at its start values the tracks move by {:.3g}σ̂² (nested below {:.3g})",
                    cand.id, moved, threshold));
  if (moved > threshold)
    throw Error(fmt::format(
        "{}: is not nested in the nominal model: at its start values it moves the tracks by "
        "{:.4g}σ̂² (noise could explain {:.3g}); start its parameters where the effect "
        "vanishes (a modulus or coefficient at 0, a multiplier at 1)",
        cand.origin, moved, threshold));
}

}  // namespace

Diagnosis run_diagnosis(const std::string& path, const std::string& outdir,
                        const DiagnoseOptions& o) {
  Diagnosis d;
  d.scenario = fs::absolute(path).lexically_normal().string();
  d.outdir = outdir;
  d.settings = load_diagnose_settings(d.scenario);
  const auto say = [&](const std::string& line) {
    if (o.progress) o.progress(line);
  };
  // Whether to stop: this rank's flag inside a task it runs alone; agreed by every
  // rank where they go on together (a SIGINT reaches them at different moments).
  const auto stopped_here = [&] { return o.interrupt && o.interrupt->load(); };
  const auto stopped = [&] { return any_interrupted(world(), stopped_here()); };
  // The models are written and read back by every rank: each in its own folder, so
  // that no two ranks replace one file.
  const fs::path out(outdir),
      state = out / "state",
      models =
          world().root() ? out / "models" : out / "models" / fmt::format("rank{}", world().rank());
  fs::create_directories(state);
  fs::create_directories(models);

  const Scenario nominal = load_scenario(d.scenario);
  if (!nominal.fit.present)
    throw Error(
        fmt::format("{}: a diagnosis needs a fit section (the nominal parameters to fit "
                    "and, optionally, fit.experiments)",
                    d.scenario));
  // The diagnosis explains a misfit to measurements; a target shape has no noise to
  // weigh it by (and its Gauss–Newton system is refused).
  const auto refuse_targets = [](const Scenario& s) {
    if (!s.fit.objective.targets.empty())
      throw Error(fmt::format(
          "{}:{}: fit.objective.targets: a diagnosis explains the gap to captured tracks; shape "
          "targets are design goals, not measurements (fit them with kelvin fit)",
          s.path, s.fit.objective.targets.front().line));
  };
  refuse_targets(nominal);
  for (const auto& file : nominal.fit.experiments)
    refuse_targets(load_scenario((fs::path(nominal.path).parent_path() / file).string()));
  const BodyAxis axis = body_axis(nominal);
  const auto wanted = [&](const Candidate& c) {
    const auto listed = [&](const std::vector<std::string>& ids) {
      return std::find(ids.begin(), ids.end(), c.id) != ids.end();
    };
    return (d.settings.candidates.empty() || listed(d.settings.candidates)) &&
           !listed(d.settings.exclude);
  };
  for (auto& c : builtin_candidates(nominal))
    if (wanted(c)) d.candidates.push_back(c);
  // The user's candidates are screened: they go before the model checks.
  auto screened_end = std::find_if(d.candidates.begin(), d.candidates.end(),
                                   [](const Candidate& c) { return !c.screened; });
  for (const auto& spec : d.settings.custom)
    if (const Candidate c = custom_candidate(spec); wanted(c))
      screened_end = d.candidates.insert(screened_end, c) + 1;
  if (d.candidates.empty())
    throw Error(
        fmt::format("{}: diagnose.candidates: none of them applies to this scenario", d.scenario));

  // ---- 1. Nominal fit ---------------------------------------------------------
  auto t0 = Clock::now();
  say(fmt::format("stage 1: nominal fit of {} ({} candidates to screen afterwards)", nominal.name,
                  d.candidates.size()));
  Model base = load_model(d.scenario, nominal, {}, false, (models / "nominal.yaml").string());
  const ParameterMap& base_map = base.problem->map();
  const int m = static_cast<int>(d.candidates.size());
  // Every verdict compares ‖r‖² between models against χ² thresholds in units of σ̂²:
  // a fit is precise enough when its relative change of Φ is a tenth of the smallest
  // threshold, at the start's ‖r‖² and noise (a single-stage fit has no other rule
  // that stops it on a flat minimum).
  const auto precision = [&](const Eigen::VectorXd& r, double sigma) {
    return 0.1 * chi_square_quantile(d.settings.alpha / m, 1) * sigma * sigma /
           std::max(r.squaredNorm(), 1e-300);
  };
  const std::string nominal_state = (state / "nominal.csv").string();
  Eigen::VectorXd p_start = base_map.initial();
  // Read on rank 0: every rank must take the same branch.
  const std::string nominal_saved =
      o.resume ? on_root([&] { return read_state(nominal_state); }) : "";
  const bool resumable =
      o.resume && saved_parameters(nominal_saved, base_map).size() == base_map.size();
  // Before any fit, so that a user's candidate that cannot be used costs little.
  for (const auto& c : d.candidates)
    if (!c.origin.empty() && !stopped() && !resumable)
      check_custom_candidate(c, nominal, *base.problem, p_start, d.settings.alpha / m, models, o);
  // A nominal fit in the wrong basin of Φ names the wrong effect (V05: ×1.67 of the
  // moduli where the truth's homogeneous fit lies at ×0.4; the refits start there).
  if (nominal.fit.start_scan != "none" && !resumable) {
    FitOptions f = fit_options_of(nominal);
    f.gradient.interrupt = o.interrupt;
    const StiffnessScan scan = scan_stiffness(*base.problem, p_start, f, o.progress);
    if (!scan.entries.empty())
      say(fmt::format("  the nominal fit starts at ×{:.3g} of the scenario's moduli", scan.scale));
    d.stiffness_scan = scan.points;
    d.stiffness_scale = scan.scale;
    p_start = scan.p;
    if (stopped()) {
      d.interrupted = true;
      return d;
    }
  }
  double nominal_ftol = 0;
  if (!resumable) {
    const GaussNewtonSystem g0 = gauss_newton_system(*base.problem, p_start, o.interrupt, false);
    if (g0.ok) {
      const NoiseEstimate n0 = estimate_noise(g0.residual, g0.samples);
      nominal_ftol = precision(g0.residual, n0.sigma);
    }
  }
  const FitRun nominal_fit = fit_model(base, p_start, nominal_state, nominal_saved, o, o.progress,
                                       "nominal", nominal_ftol);
  if (!nominal_fit.ok) throw Error(fmt::format("the nominal fit failed: {}", nominal_fit.error));
  if (nominal_fit.finished)
    on_root([&] {
      save_parameters(nominal_state, labels_of(base_map), nominal_fit.p);
      return std::string();
    });
  const Eigen::VectorXd p_nominal = nominal_fit.p;
  d.nominal_evaluations = nominal_fit.evaluations;
  d.nominal_parameters = named_values(base_map, p_nominal, range(base_map.size()));
  d.seconds.nominal_fit = since(t0);
  if (stopped()) {
    d.interrupted = true;
    return d;
  }

  // ---- 2./3. Screening at the nominal fit --------------------------------------
  t0 = Clock::now();
  std::vector<const Candidate*> all;  // the screened ones, which come first
  for (const auto& c : d.candidates)
    if (c.screened) all.push_back(&c);
  say(fmt::format("stage 2: residual and screening of {} candidates at the nominal fit",
                  all.size()));
  Model screen = load_model(d.scenario, nominal, all, true, (models / "screening.yaml").string());
  const ParameterMap& smap = screen.problem->map();
  const int n_nominal = base_map.size();
  for (int j = 0; j < n_nominal; ++j)
    if (smap.label(j) != base_map.label(j))
      throw Error(
          fmt::format("internal: the screening model's parameter {} is '{}', the "
                      "nominal's '{}'",
                      j, smap.label(j), base_map.label(j)));
  Eigen::VectorXd p_screen = smap.initial();
  p_screen.head(n_nominal) = p_nominal;
  // The seconds of each screening run, which balance the ranks in the next ones.
  ScreeningCosts screening_costs;
  const GaussNewtonSystem g =
      screening_system(screen, d.scenario, nominal, all, -1, p_screen, models, "screening",
                       o.interrupt, world(), nullptr, &screening_costs);
  if (!g.ok) throw Error(fmt::format("the screening run failed: {}", g.error));
  d.noise = estimate_noise(g.residual, g.samples);
  {
    // The nominal parameters' standard errors from the screening's own columns.
    GaussNewtonSystem nominal_system;
    nominal_system.ok = true;
    nominal_system.residual = g.residual;
    nominal_system.jacobian = g.jacobian.leftCols(n_nominal);
    nominal_system.rtol = g.rtol;
    const ParameterUncertainty u =
        with_held_errors(gauss_newton_uncertainty(smap, p_screen, nominal_system), smap, p_screen);
    d.nominal_parameters = named_values(base_map, p_nominal, range(n_nominal), &u);
    d.nominal_errors_note = u.ok ? u.error : "no standard errors: " + u.error;
  }
  d.nominal_train.ok = true;
  d.nominal_train.residual = g.residual;
  d.nominal_train.samples = static_cast<int>(g.residual.size());
  d.nominal_train.sum_sq = g.residual.squaredNorm();
  d.nominal_train.rms = std::sqrt(d.nominal_train.sum_sq / std::max(1, d.nominal_train.samples));
  d.nominal_samples = g.samples;
  d.marker_names = screen.problem->experiment(0).objective().names();
  d.where = locate_residual(*screen.problem, g.residual, g.samples, axis, d.noise.sigma);
  say(
      fmt::format("  nominal rms {:.4f} mm per coordinate; noise {:.4f} mm (from {} third "
                  "differences)",
                  d.nominal_train.rms * 1e3, d.noise.sigma * 1e3, d.noise.differences));
  d.seconds.screening = since(t0);
  // The missing force's basis; the field is fitted beside the refits (stage 3).
  MissingForceSettings mfs = d.settings.missing_force;
  bool force_wanted = false;
  if (d.settings.missing_force.enabled && !stopped()) {
    if (mfs.knots_per_second <= 0) {
      // Four knots per period at the top of the band that brings the residual's power
      // to 90 %, but no faster than the observed motion (95 % of its power; a short
      // capture leaks the rest upwards): a noise residual is white, and a force above
      // the motion's band would only fit noise.
      const auto top = [&](double fraction, bool residual) {
        double cumulative = 0, f = 0;
        for (const auto& b : d.where.bands) {
          f = b.f1;
          if ((cumulative += residual ? b.residual_fraction : b.signal_fraction) >= fraction) break;
        }
        return f;
      };
      mfs.knots_per_second =
          4 * std::max(std::min(top(0.9, true), top(0.95, false)), 1 / nominal.time.end);
    }
    force_wanted = true;
  }
  t0 = Clock::now();

  std::vector<std::pair<std::string, std::vector<int>>> groups;
  ScreeningOptions so;
  so.noise_variance = d.noise.sigma * d.noise.sigma;
  so.held = unresolved_entries(smap, p_screen, g.jacobian, d.noise.sigma, range(n_nominal));
  for (int j : so.held)
    say(
        fmt::format("  {} moves the markers too little for the data to place it: the "
                    "linearised starts of the refits keep it at its nominal value",
                    smap.label(j)));
  const Eigen::VectorXd lo = smap.lower(), start = smap.initial();
  for (std::size_t c = 0; c < all.size(); ++c) {
    const std::vector<int> e = entries_of(screen, screen.extended.candidate_specs[c]);
    groups.emplace_back(slug(*all[c]), e);
    for (int j : e)
      if (lo[j] == start[j]) so.nonnegative.push_back(j);
  }
  d.ranking =
      rank_candidates(g.residual, g.jacobian, range(n_nominal), groups, so, d.settings.alpha);
  // A candidate screened as alternatives (the anisotropy's directions, the
  // relaxation's times) is refitted from the one that explains most, from its
  // Gauss–Newton step.
  std::map<int, CandidateScore> start_scores;
  for (std::size_t c = 0; c < all.size(); ++c)
    if (d.candidates[c].alternatives)
      start_scores[static_cast<int>(c)] =
          chosen_alternative(g, n_nominal, groups[c].second, so, smap, d.candidates[c].choice);
  d.seconds.screening += since(t0);
  for (const auto& rc : d.ranking.order)
    say(fmt::format(
        "  {:<22} LM {:10.1f}  (threshold {:7.1f}, dof {})  predicted rms "
        "{:.4f} mm{}",
        groups[rc.candidate].first, rc.marginal.statistic, rc.threshold, rc.marginal.dof,
        rc.marginal.predicted_rms * 1e3, rc.significant ? "  significant" : ""));
  if (stopped()) {
    d.interrupted = true;
    return d;
  }

  // Held-out figures of the nominal model.
  auto th = Clock::now();
  std::vector<Model> heldout_nominal;
  for (std::size_t k = 0; k < d.settings.validate.size(); ++k) {
    Model h = load_model(d.settings.validate[k], nominal, {}, false,
                         (models / fmt::format("heldout{}-nominal.yaml", k)).string());
    if (h.problem->map().size() != n_nominal)
      throw Error(
          fmt::format("{}: its parameters do not match the training scenario's "
                      "(another mesh or markers?)",
                      d.settings.validate[k]));
    HeldOutFigures f;
    f.path = d.settings.validate[k];
    f.marker_names = h.problem->experiment(0).objective().names();
    f.before = misfit(*h.problem, p_nominal, o.interrupt);
    if (!f.before.ok) throw Error(fmt::format("{}: {}", f.path, f.before.error));
    say(fmt::format("  held-out {}: nominal rms {:.4f} mm", fs::path(f.path).filename().string(),
                    f.before.rms * 1e3));
    d.nominal_heldout.push_back(f);
  }
  d.seconds.heldout += since(th);

  // ---- 3. Refits of the top candidates ----------------------------------------
  t0 = Clock::now();
  const double sigma2 = d.noise.sigma * d.noise.sigma;
  const double N = d.nominal_train.samples;
  std::vector<int> order;
  std::map<int, CandidateScore> marginal;  // by candidate
  std::map<int, double> threshold;
  for (const auto& rc : d.ranking.order) {
    order.push_back(rc.candidate);
    marginal[rc.candidate] = rc.marginal;
    threshold[rc.candidate] = rc.threshold;
  }
  // A one-parameter candidate whose score does not clear its threshold may still be
  // an effect too large for the linearisation: V08's compliant clamp scored 0 at a
  // nominal fit 20× the noise, while one run at the compliance's typical size dropped
  // the rms from 18.6 to 4.3 mm; V03's flow index h = 0.6 scored 2.4 at h = 1, where
  // the nominal viscosity absorbs its first-order effect, while the truth's h lowers
  // ‖r‖² by ~210 σ̂². Such a candidate gets runs at its typical size (a bounded one
  // above its bound; a free one on both sides, e^±½ for a log parameter), each
  // followed by one Gauss–Newton step of the nominal parameters on the screening's
  // Jacobian (they compensate for the effect, as the nominal fit did for its absence)
  // and a run there. The best LR, a lower bound on the refit's, stands in for the
  // score, and the refit starts there.
  std::map<int, Eigen::VectorXd> probe_start;
  const Eigen::MatrixXd nominal_columns = g.jacobian.leftCols(n_nominal);
  const auto nominal_step = nominal_columns.completeOrthogonalDecomposition();
  std::vector<int> probed;
  for (const auto& rc : d.ranking.order) {
    const int c = rc.candidate;
    if (!stopped() && rc.marginal.error.empty() && groups[c].second.size() == 1 &&
        rc.marginal.statistic <= rc.threshold)
      probed.push_back(c);
  }
  // Its probes, on this rank alone: the best LR above the score's, and where (an empty
  // p when none is).
  const auto probe = [&](int c, const ProgressLine& line) {
    const int e = groups[c].second[0];
    const bool at_bound =
        std::find(so.nonnegative.begin(), so.nonnegative.end(), e) != so.nonnegative.end();
    const Candidate& cand = d.candidates[c];
    Model model = load_model(d.scenario, nominal, {&cand}, false,
                             (models / (slug(cand) + ".yaml")).string(), -1, serial_communicator());
    const ParameterMap& map = model.problem->map();
    const int j = entries_of(model, model.extended.candidate_specs[0])[0];
    Eigen::VectorXd p0 = map.initial();
    p0.head(n_nominal) = p_nominal;
    const double size = map.is_log(j) ? 0.5 : map.units()[j];
    std::vector<double> values;
    if (at_bound)
      values = {std::min(map.lower()[j] + map.units()[j], map.upper()[j])};
    else
      for (double sign : {-1.0, 1.0})
        values.push_back(std::clamp(p0[j] + sign * size, map.lower()[j], map.upper()[j]));
    double best = marginal.at(c).statistic;
    Eigen::VectorXd start;
    for (double value : values) {
      if (stopped_here() || value == p0[j]) continue;
      Eigen::VectorXd p = p0;
      p[j] = value;
      MisfitFigures f = misfit(*model.problem, p, o.interrupt);
      if (!f.ok || f.residual.size() != g.residual.size()) continue;
      Eigen::VectorXd q = p;
      q.head(n_nominal) -= nominal_step.solve(f.residual);
      q = q.cwiseMax(map.lower()).cwiseMin(map.upper());
      const MisfitFigures fq = misfit(*model.problem, q, o.interrupt);
      const bool adjusted = fq.ok && fq.sum_sq < f.sum_sq;
      if (adjusted) {
        f = fq;
        p = q;
      }
      const double lr = (d.nominal_train.sum_sq - f.sum_sq) / sigma2;
      line(fmt::format("  {:<22} probe at {} = {:.4g}{}: rms {:.4f} mm, LR {:.1f}", slug(cand),
                       map.label(j), map.value(p, j),
                       adjusted ? " (nominal parameters re-adjusted)" : "", f.rms * 1e3, lr));
      if (lr <= best) continue;
      best = lr;
      start = p;
    }
    ByteWriter bytes;
    bytes.put(best);
    bytes.put(start);
    return bytes.bytes();
  };
  // A candidate without parameters of its own (the discretisation) has no score and
  // no linearisation: one run of its model at the nominal fit says whether the tracks
  // move beyond the noise, S = ‖r_fine − r‖²/σ̂² against χ²(α/m, 1). When they do, the
  // fitted parameters may be bent by the mesh and only a refit can tell: it gets one of
  // its own, besides the physical candidates'. No linearisation stands in for it: on a
  // shaken bar the change's part the nominal parameters cannot absorb predicted
  // 0.205 mm with them refitted, three Gauss–Newton steps reached 0.17, the refit 0.010
  // (the coarse fit's ν 4.4 against the fine mesh's 20).
  std::vector<int> checked;  // the unscreened candidates
  for (int c = static_cast<int>(all.size()); c < m && !stopped(); ++c) checked.push_back(c);
  // Its model at the nominal fit, on this rank alone: what it moves the tracks by.
  const auto check = [&](int c, const ProgressLine&) {
    if (stopped_here()) return std::string();  // not judged, not listed
    const Candidate& cand = d.candidates[c];
    Model model = load_model(d.scenario, nominal, {&cand}, false,
                             (models / (slug(cand) + ".yaml")).string(), -1, serial_communicator());
    const ParameterMap& map = model.problem->map();
    bool same = map.size() == n_nominal;
    for (int j = 0; same && j < n_nominal; ++j) same = map.label(j) == base_map.label(j);
    std::string error = same ? "" : "its parameters differ from the nominal model's";
    double statistic = 0, rms = 0;
    if (same) {
      const MisfitFigures f = misfit(*model.problem, p_nominal, o.interrupt);
      if (!f.ok)
        error = f.error;
      else if (f.residual.size() != d.nominal_train.residual.size())
        error = "its markers see other samples than the nominal's";
      else {
        statistic = (f.residual - d.nominal_train.residual).squaredNorm() / sigma2;
        rms = f.rms;
      }
    }
    ByteWriter bytes;
    bytes.put(error);
    bytes.put(statistic);
    bytes.put(rms);
    return bytes.bytes();
  };
  const int n_probed = static_cast<int>(probed.size());
  const std::vector<std::string> runs = spread_tasks(
      world(), n_probed + static_cast<int>(checked.size()),
      [&](int k, const ProgressLine& line) {
        return k < n_probed ? probe(probed[k], line) : check(checked[k - n_probed], line);
      },
      o.progress, o.interrupt);
  for (int k = 0; k < n_probed; ++k) {
    ByteReader in(runs[k]);
    double best = 0;
    Eigen::VectorXd start;
    in.get(best);
    in.get(start);
    if (start.size() == 0) continue;
    marginal[probed[k]].statistic = best;
    probe_start[probed[k]] = start;
  }
  std::vector<int> model_checks;  // unscreened candidates whose model moves the tracks
  for (std::size_t k = 0; k < checked.size(); ++k) {
    const int c = checked[k];
    if (runs[n_probed + k].empty()) continue;
    RankedCandidate rc;
    rc.candidate = c;
    rc.marginal.name = slug(d.candidates[c]);
    rc.marginal.rms_before = d.nominal_train.rms;
    rc.threshold = chi_square_quantile(d.settings.alpha / m, 1);
    ByteReader in(runs[n_probed + k]);
    in.get(rc.marginal.error);
    in.get(rc.marginal.statistic);
    in.get(rc.marginal.predicted_rms);
    if (rc.marginal.error.empty()) {
      rc.significant = rc.marginal.statistic > rc.threshold;
      probe_start[c] = p_nominal;
      if (rc.significant) model_checks.push_back(c);
    }
    say(fmt::format(
        "  {:<22} {}", rc.marginal.name,
        rc.marginal.error.empty()
            ? fmt::format("moves the tracks by {:.1f}σ̂² at the nominal fit (threshold {:.1f}, "
                          "rms there {:.4f} mm){}",
                          rc.marginal.statistic, rc.threshold, rc.marginal.predicted_rms * 1e3,
                          rc.significant ? ": a refit, unless the others leave only noise" : "")
            : "not judged: " + rc.marginal.error));
    d.ranking.order.push_back(rc);
  }
  d.seconds.screening += since(t0);  // the probes and the model checks
  // Refit by the marginal statistic: the greedy order credits an effect once, but
  // which of two confounded ones to refit is the refit's question.
  const auto strength = [&](int c) {
    const CandidateScore& x = marginal.at(c);
    return x.error.empty() ? x.statistic / chi_square_quantile(0.01, std::max(1, x.dof)) : -1.0;
  };
  std::sort(order.begin(), order.end(), [&](int a, int b) { return strength(a) > strength(b); });
  // Refit those whose marginal score clears its threshold; when none does, the top one
  // alone, in case its effect is too far from linear for the local test (a long lag).
  int passing = 0;
  for (const auto& [c, x] : marginal) passing += x.error.empty() && x.statistic > threshold[c];
  d.predicted_heldout_drop.assign(d.candidates.size(), std::numeric_limits<double>::quiet_NaN());
  if (passing > d.settings.refits && !d.settings.validate.empty() && !stopped()) {
    th = Clock::now();
    say(
        fmt::format("  {} candidates cleared the threshold and {} are refitted: the held-out "
                    "motions choose (each one's screening step, predicted there)",
                    passing, d.settings.refits));
    predict_heldout_drops(d, order, marginal, threshold, probe_start, all, smap, p_screen,
                          n_nominal, nominal, models, o, screening_costs);
    d.seconds.heldout += since(th);
    std::vector<int> passed, rest;
    for (int c : order) (std::isfinite(d.predicted_heldout_drop[c]) ? passed : rest).push_back(c);
    order = order_by_heldout(passed, d.predicted_heldout_drop);
    order.insert(order.end(), rest.begin(), rest.end());
    d.refit_order_from_heldout = !passed.empty();
  }
  const int K =
      std::min<int>({d.settings.refits, static_cast<int>(order.size()), std::max(passing, 1)});
  // The family tested on the held-out motions: the refits (or every candidate they
  // were chosen from, when the held-out predictions chose them), the model checks
  // and the learned correction, each at α over their number.
  const int heldout_tests = (d.refit_order_from_heldout ? std::max(passing, K) : K) +
                            static_cast<int>(model_checks.size()) +
                            (d.settings.learned_correction ? 1 : 0);
  say(fmt::format(
      "stage 3: refits of the top {} candidates ({} cleared the screening threshold){}{}", K,
      passing,
      model_checks.empty() ? std::string()
                           : fmt::format(", and of {} model check(s)", model_checks.size()),
      force_wanted ? "; the missing force beside them" : ""));
  // The linearised start p0 (a Gauss–Newton step from the nominal) can overshoot
  // far past the valley it points into (V06: 8.55 mm from a nominal of 0.95 mm, and
  // the refit spent its budget coming back): halve the step until it beats the
  // nominal, three times at most, else start at the nominal. A refit resumed from its
  // saved state skips it; one that has none yet starts like a new one (V07 resumed
  // after its nominal fit started its anisotropy refit at the unchecked step: 9.13 mm
  // against the nominal's 1.37).
  const auto linearised_start = [&](Model& model, const Eigen::VectorXd& p0, double reference,
                                    const Eigen::VectorXd& nominal_p, const std::string& name,
                                    const ProgressLine& say) {
    if ((o.resume && fs::exists(state / (name + ".csv"))) || (p0 - nominal_p).norm() == 0)
      return p0;
    Eigen::VectorXd p = p0;
    for (int halving = 0; halving <= 3 && !stopped_here(); ++halving) {
      const MisfitFigures at = misfit(*model.problem, p, o.interrupt);
      if (at.ok && at.sum_sq < reference) {
        if (halving > 0)
          say(
              fmt::format("  {}: the linearised start overshoots; starting at {}/{} of its step "
                          "(train rms {:.4f} mm)",
                          name, 1, 1 << halving, at.rms * 1e3));
        return p;
      }
      p = nominal_p + 0.5 * (p - nominal_p);
    }
    if (stopped_here()) return nominal_p;
    say(
        fmt::format("  {}: the linearised start and its halvings are worse than the model "
                    "without the effect; starting at its fit",
                    name));
    return nominal_p;
  };
  // What a refit is measured against: the nominal model, or (the second stage) the
  // model with an accepted effect at its refit. The candidate is nested in it.
  struct RefitBase {
    std::vector<const Candidate*> with;    // effects in the model already
    Eigen::VectorXd p;                     // its fitted parameters, leading the map
    const MisfitFigures* train = nullptr;  // its training misfit
    std::vector<HeldOutFigures> heldout;   // `before`: its held-out misfits
    int tests = 1, heldout_tests = 1;      // α is shared over these
    std::string prefix;                    // of the refit's file names
    int on_top_of = -1;                    // RefitResult::on_top_of
    std::string name = "the nominal";
  };
  RefitBase nominal_base;
  nominal_base.p = p_nominal;
  nominal_base.train = &d.nominal_train;
  nominal_base.heldout = d.nominal_heldout;
  nominal_base.tests = m;
  nominal_base.heldout_tests = heldout_tests;
  // One candidate's refit with the base's parameters free, from `start(model,
  // entries)` (the candidate's entries of the model's map), and its held-out checks,
  // on this rank alone, which saves the fit's parameters as soon as it has ended (the
  // ranks' state files are theirs: --resume needs them on one file system);
  // `heldout_seconds` the time of the held-out checks.
  using Start = std::function<Eigen::VectorXd(Model&, const std::vector<int>&)>;
  const auto refit = [&](int c, const Start& start, const ProgressLine& say,
                         double& heldout_seconds, const RefitBase& base) {
    const Candidate& cand = d.candidates[c];
    RefitResult res;
    res.candidate = c;
    res.on_top_of = base.on_top_of;
    const std::string name = base.prefix + slug(cand);
    std::vector<const Candidate*> with = base.with;
    with.push_back(&cand);
    Model model = load_model(d.scenario, nominal, with, false, (models / (name + ".yaml")).string(),
                             -1, serial_communicator());
    const ParameterMap& map = model.problem->map();
    const std::vector<int> entries = entries_of(model, model.extended.candidate_specs.back());
    res.dof = static_cast<int>(entries.size());
    const Eigen::VectorXd p0 = start(model, entries).cwiseMax(map.lower()).cwiseMin(map.upper());
    const int n_fixed = static_cast<int>(base.p.size());
    // The base's fit inside the extended model (the candidate at its nested value).
    const auto nested_nominal = [&] {
      Eigen::VectorXd p = map.initial();
      p.head(n_fixed) = base.p;
      return p;
    };
    const double refit_ftol = precision(base.train->residual, d.noise.sigma);
    const Eigen::VectorXd p_start =
        linearised_start(model, p0, base.train->sum_sq, nested_nominal(), name, say);
    const std::string saved_at = (state / (name + ".csv")).string(),
                      saved = o.resume ? read_state(saved_at) : "";
    FitRun fit = fit_model(model, p_start, saved_at, saved, o, say, name, refit_ftol,
                           d.settings.refit_evaluations);
    if (!fit.ok && !stopped_here()) {
      // The linearised start may lie where the model cannot run: from the nominal.
      fit = fit_model(model, nested_nominal(), saved_at, saved, o, say, name, refit_ftol,
                      d.settings.refit_evaluations);
    }
    if (fit.finished) save_parameters(saved_at, labels_of(map), fit.p);
    res.evaluations = fit.evaluations;
    if (!fit.ok) {
      res.error = fit.error;
      return res;
    }
    res.train = misfit(*model.problem, fit.p, o.interrupt);
    if (!res.train.ok) {
      res.error = res.train.error;
      return res;
    }
    // The refined mesh does not contain the nominal model; every other candidate does.
    if (res.train.sum_sq > base.train->sum_sq && cand.id != "discretisation") {
      say(
          fmt::format("  {}: the refit ended above {} (train rms {:.4f} mm against "
                      "{:.4f}); reported at its point",
                      name, base.name, res.train.rms * 1e3, base.train->rms * 1e3));
      fit.p = nested_nominal();
      res.train = *base.train;
      res.at_nominal = true;
    }
    res.ok = true;
    res.statistic = (base.train->sum_sq - res.train.sum_sq) / sigma2;
    res.threshold = chi_square_quantile(d.settings.alpha / base.tests, std::max(1, res.dof));
    res.bic = res.train.sum_sq / sigma2 + (n_fixed + res.dof) * std::log(N);
    res.passes_training = res.statistic > res.threshold;
    res.parameters = named_values(map, fit.p, entries);
    res.nominal_parameters = named_values(map, fit.p, range(n_fixed));
    res.p = fit.p;
    for (int j = 0; j < map.size(); ++j) res.labels.push_back(map.label(j));
    if (cand.id == "marker_offset" || cand.id == "sync_lag" || cand.id == "registration" ||
        cand.id == "discretisation")
      res.where = cand.where;
    else if (cand.id == "inhomogeneity" || cand.id == "added_mass")
      res.where = field_region(model, fit.p, nominal, cand.id == "added_mass", axis);
    else if (cand.id == "clamp_compliance")  // where the pads are, by construction
      res.where = cand.where.empty() ? "clamp zone" : "clamp zone (" + cand.where + ")";
    else if (!cand.origin.empty())  // the user's word for where the effect acts
      res.where = cand.where;
    // Held-out motions.
    const auto th = Clock::now();
    double spread = 0;
    for (std::size_t k = 0; k < d.settings.validate.size() && !stopped_here(); ++k) {
      Model h = load_model(d.settings.validate[k], nominal, with, false,
                           (models / fmt::format("heldout{}-{}.yaml", k, name)).string(), -1,
                           serial_communicator());
      HeldOutFigures f = k < base.heldout.size() ? base.heldout[k] : HeldOutFigures();
      if (!f.before.ok) {
        f.after.error = "the model it is added to has no misfit there to compare with";
      } else if (h.problem->map().size() != map.size()) {
        f.after.error = "its parameters do not match the training scenario's";
      } else if (res.at_nominal) {
        f.after = f.before;
      } else {
        f.after = misfit(*h.problem, fit.p, o.interrupt);
      }
      if (f.after.ok && f.after.samples == f.before.samples) {
        res.heldout_drop += f.before.sum_sq - f.after.sum_sq;
        spread += (f.after.residual - f.before.residual).squaredNorm();
      }
      res.heldout.push_back(f);
    }
    heldout_seconds = since(th);
    res.heldout_threshold = 2 * normal_quantile(d.settings.alpha / base.heldout_tests) *
                            d.noise.sigma * std::sqrt(spread);
    res.passes_heldout = !res.heldout.empty() && res.heldout_drop > res.heldout_threshold;
    // Standard errors where the parameters mean something: a refit that explains more
    // than noise (one sensitivity solve at its point).
    if (res.passes_training && !res.at_nominal && !stopped_here()) {
      const ParameterUncertainty u = with_held_errors(
          gauss_newton_uncertainty(*model.problem, fit.p, o.interrupt), map, fit.p);
      res.errors_note = u.ok ? u.error : "no standard errors: " + u.error;
      if (!res.errors_note.empty()) say(fmt::format("  {}: {}", name, res.errors_note));
      if (u.ok) {
        res.parameters = named_values(map, fit.p, entries, &u);
        res.nominal_parameters = named_values(map, fit.p, range(n_fixed), &u);
        for (const NamedValue& v : res.parameters)
          if (std::isfinite(v.std_error))
            say(fmt::format("  {}: {} = {:.5g} ± {:.2g}", name, v.name, v.value, v.std_error));
      }
    }
    double after = 0, before = 0;
    for (const auto& f : res.heldout) {
      before += f.before.sum_sq;
      after += f.after.ok ? f.after.sum_sq : f.before.sum_sq;
    }
    say(fmt::format("  {}: train rms {:.4f} → {:.4f} mm (LR {:.1f}, threshold {:.1f}){}", name,
                    base.train->rms * 1e3, res.train.rms * 1e3, res.statistic, res.threshold,
                    res.heldout.empty()
                        ? std::string()
                        : fmt::format("; held-out ‖r‖² {:.4g} → {:.4g} mm² (needs a drop > "
                                      "{:.3g})",
                                      before * 1e6, after * 1e6, res.heldout_threshold * 1e6)));
    return res;
  };
  // The missing force of `problem` at p, fitted on this rank alone into outdir/`dir`
  // and summed up in a line that starts with `what`: a task of spread_tasks, packed.
  const auto missing_force_task = [&](FitProblem& problem, const Scenario& s,
                                      const Eigen::VectorXd& p, const std::string& dir,
                                      const std::string& what, const ProgressLine& line) {
    const MissingForce f = fit_missing_force(
        problem, s, p, axis, {d.noise.sigma, d.nominal_train.samples, d.settings.alpha}, mfs,
        (out / dir).string(), o.interrupt, line, serial_communicator());
    line(fmt::format("  {}: {}", what, describe(f)));
    ByteWriter bytes;
    put(bytes, f);
    return bytes.bytes();
  };
  const auto unpacked_force = [](const std::string& bytes) {
    MissingForce f;
    ByteReader in(bytes);
    get(in, f);
    return f;
  };
  // A refit as a task of spread_tasks: packed, timed; not run ("") after an interrupt.
  const auto refit_task = [&](int c, const Start& start, const ProgressLine& say,
                              const RefitBase& base) {
    if (stopped_here()) return std::string();
    const auto tr = Clock::now();
    double heldout_seconds = 0;
    RefitResult res = refit(c, start, say, heldout_seconds, base);
    res.seconds = since(tr);
    ByteWriter bytes;
    put(bytes, res);
    bytes.put(heldout_seconds);
    return bytes.bytes();
  };
  // A gathered refit, on every rank: rank 0 writes its refitted scenario; its time
  // counts to `stage`. Returns it (empty when it did not run).
  const auto gathered_refit = [&](const std::string& bytes, double& stage, const RefitBase& base) {
    std::optional<RefitResult> gathered;
    if (bytes.empty()) return gathered;
    RefitResult res;
    double heldout_seconds = 0;
    ByteReader in(bytes);
    get(in, res);
    in.get(heldout_seconds);
    const Candidate& cand = d.candidates[res.candidate];
    const std::string name = base.prefix + slug(cand);
    std::vector<const Candidate*> with = base.with;
    with.push_back(&cand);
    res.fitted_yaml = on_root([&] {
      if (!res.ok) return std::string();
      Model model = load_model(d.scenario, nominal, with, false,
                               (models / (name + ".yaml")).string(), -1, serial_communicator());
      FemModel& fem = model.problem->experiment(0).model();
      model.problem->map().apply(res.p, fem);
      return write_fitted_scenario(*model.scenario, model.problem->map(), fem,
                                   (out / "refits" / name).string(), res.p);
    });
    stage += res.seconds;
    d.seconds.heldout += heldout_seconds;
    gathered = std::move(res);
    return gathered;
  };
  const auto take_refit = [&](const std::string& bytes, double& stage) {
    if (auto res = gathered_refit(bytes, stage, nominal_base)) d.refits.push_back(std::move(*res));
  };
  // The start of a top candidate's refit: from its probe, or its screening step.
  const auto screening_start = [&](int c) {
    return [&, c](Model& model, const std::vector<int>& entries) {
      const ParameterMap& map = model.problem->map();
      if (probe_start.count(c)) return Eigen::VectorXd(probe_start.at(c));
      const CandidateScore& score = start_scores.count(c) ? start_scores.at(c) : marginal.at(c);
      return start_from_score(map, p_nominal, score, d.candidates[c].alternatives, groups[c].second,
                              entries);
    };
  };
  // The missing force of the nominal model needs none of the screening's results
  // after the noise level, and no refit needs it: it runs beside the refits (task 0).
  const int with_force = force_wanted && !stopped() ? 1 : 0;
  const std::vector<std::string> stage3 = spread_tasks(
      world(), with_force + K,
      [&](int k, const ProgressLine& line) {
        if (k >= with_force) {
          const int c = order[k - with_force];
          return refit_task(c, screening_start(c), line, nominal_base);
        }
        line(fmt::format("  missing force: {} knots in time × {} segments × 3 axes, {} evaluations",
                         std::lround(mfs.knots_per_second * nominal.time.end), mfs.segments,
                         mfs.evaluations));
        return missing_force_task(*base.problem, nominal, p_nominal, "missing-force",
                                  "missing force", line);
      },
      o.progress, o.interrupt);
  if (with_force) {
    d.missing_force = unpacked_force(stage3[0]);
    d.seconds.missing_force = d.missing_force.seconds;
  }
  for (int k = with_force; k < with_force + K; ++k) take_refit(stage3[k], d.seconds.refits);
  // ‖r‖²/(N − n) over σ̂² is an F ratio on N − n and M degrees of freedom (M third
  // differences), whose logarithm is about normal with variance 2/(N − n) + 2/M;
  // tested at α/m like every candidate (V01, no effect: 0.502 mm against σ̂ 0.492, a
  // log ratio of 0.040 where α/m puts the bar at about 0.07 and α alone at 0.05).
  const auto noise_ratio = [&](double sum_sq, int parameters) {
    return sum_sq / std::max(1.0, N - parameters) / sigma2;
  };
  const auto more_than_noise = [&](double sum_sq, int parameters) {
    const double dof = std::max(1.0, N - parameters);
    return std::log(noise_ratio(sum_sq, parameters)) >
           normal_quantile(d.settings.alpha / m) *
               std::sqrt(2 / dof + 2.0 / std::max(1, d.noise.differences));
  };
  // The mesh is refitted when a gap is left that it could explain: not when the
  // nominal fit, or a physical effect's refit that passes, leaves only noise.
  const bool judged_on_heldout = !d.settings.validate.empty();
  const auto passes = [&](const RefitResult& x) {
    return x.ok && x.passes_training && (!judged_on_heldout || x.passes_heldout);
  };
  std::string explained;
  if (!more_than_noise(d.nominal_train.sum_sq, n_nominal)) explained = "the nominal fit";
  for (const auto& x : d.refits)
    if (explained.empty() && passes(x) && !more_than_noise(x.train.sum_sq, n_nominal + x.dof))
      explained = slug(d.candidates[x.candidate]);
  std::vector<int> checks;  // the model checks refitted
  for (int c : model_checks) {
    if (stopped()) break;
    if (explained.empty())
      checks.push_back(c);
    else
      say(fmt::format("  {}: not refitted: {} leaves only noise", slug(d.candidates[c]),
                      explained));
  }
  for (const std::string& bytes : spread_tasks(
           world(), static_cast<int>(checks.size()),
           [&](int k, const ProgressLine&say) {
             const int c = checks[k];
             return refit_task(
                 c,
                 [&](Model&, const std::vector<int>&) {
                   return Eigen::VectorXd(probe_start.at(c));
                 },
                 say, nominal_base);
           },
           o.progress, o.interrupt))
    take_refit(bytes, d.seconds.refits);

  // ---- Verdict -------------------------------------------------------------------
  for (int r = 0; r < static_cast<int>(d.refits.size()); ++r) {
    const RefitResult& x = d.refits[r];
    if (!passes(x)) continue;
    if (d.accepted < 0) {
      d.accepted = r;
      continue;
    }
    const RefitResult& y = d.refits[d.accepted];
    if (judged_on_heldout ? x.heldout_drop > y.heldout_drop : x.bic < y.bic) d.accepted = r;
  }
  // ---- 5. The unnamed effect -----------------------------------------------------
  // Only when something is missing and no named candidate took it: the missing force
  // found more than noise, or the nominal residual is above it.
  const bool above_noise = more_than_noise(d.nominal_train.sum_sq, n_nominal);
  const bool something_missing =
      above_noise || (d.missing_force.ok && d.missing_force.statistic > d.missing_force.threshold);
  if (d.accepted < 0 && d.settings.learned_correction && something_missing && !stopped()) {
    say(fmt::format(
        "stage 5: no named candidate explains the gap (nominal ‖r‖² {:.2f}× the noise's): "
        "a learned stress correction",
        noise_ratio(d.nominal_train.sum_sq, n_nominal)));
    d.candidates.push_back(learned_correction(nominal));
    const int c = static_cast<int>(d.candidates.size()) - 1;
    // From the Gauss–Newton step at the nominal fit: the correction is linear in its
    // values, and L-BFGS from zero crawls along their weakly coupled directions (12
    // evaluations took a bulk-modulus error a tenth of the way). The minimum-norm
    // step leaves the values the data do not see at 0.
    const Start start = [&](Model& model, const std::vector<int>&) {
      Eigen::VectorXd p0 = model.problem->map().initial();
      p0.head(n_nominal) = p_nominal;
      if (o.resume && fs::exists(state / "unnamed.csv")) return p0;  // the refit is saved
      const GaussNewtonSystem gn = gauss_newton_system(*model.problem, p0, o.interrupt);
      if (gn.ok) p0 -= gn.jacobian.completeOrthogonalDecomposition().solve(gn.residual);
      return p0;
    };
    take_refit(
        spread_tasks(
            world(), 1,
            [&](int, const ProgressLine& line) { return refit_task(c, start, line, nominal_base); },
            o.progress, o.interrupt)[0],
        d.seconds.learned_correction);
    if (d.refits.empty() || d.refits.back().candidate != c) {
      d.candidates.pop_back();  // interrupted before it began
    } else {
      const RefitResult& res = d.refits.back();
      if (res.ok) {
        d.signature = correction_signature(nominal, res.parameters);
        say("  signature: " + d.signature.summary);
      }
      d.learned = static_cast<int>(d.refits.size()) - 1;
      if (res.ok && res.passes_training && (!judged_on_heldout || res.passes_heldout))
        d.accepted = d.learned;
    }
  }
  if (d.accepted >= 0) {
    const RefitResult& a = d.refits[d.accepted];
    d.effect = d.candidates[a.candidate].id;
    d.fitted_yaml = a.fitted_yaml;
    std::string where = a.where;
    if (where.empty()) {
      // The region whose markers carry most of the model's residual.
      const RegionResidual* worst = nullptr;
      for (const auto& reg : d.where.regions)
        if (!worst || reg.excess > worst->excess) worst = &reg;
      if (worst) where = worst->name;
    }
    if (!where.empty()) d.verdict_where.push_back(where);
    // Screen again with the accepted effect in the model, at its refit (after the
    // unnamed one, every named candidate has been refitted and failed already).
    // How far it shrinks, as a force: the missing force of the model with the effect,
    // fitted beside the second screening (neither needs the other).
    const RefitResult& x = d.refits[d.accepted];
    std::optional<Model> accepted;
    BesideTask remaining{nullptr, o.progress, ""};
    if (d.settings.missing_force.enabled && mfs.knots_per_second > 0 && !stopped()) {
      accepted = load_model(d.scenario, nominal, {&d.candidates[x.candidate]}, false,
                            (models / "accepted.yaml").string(), -1, serial_communicator());
      if (!accepted->problem->map().observation_blocks().empty())
        // The field is fitted to a scenario file holding the model at its refit, and
        // a clock offset, marker offset or registration has no place in one yet.
        d.remaining_force.error = fmt::format(
            "not computed: {} is a parameter of the observation, which a scenario file "
            "cannot hold fixed",
            d.effect);
      else
        remaining.run = [&](int, const ProgressLine& line) {
          return missing_force_task(*accepted->problem, *accepted->scenario, x.p,
                                    "missing-force-after", "missing force left", line);
        };
    }
    bool beside = false;  // the field was fitted beside the second screening
    Start second_start;   // of the second candidate's refit, when one is significant
    if (!stopped() && d.accepted != d.learned) {
      t0 = Clock::now();
      say(fmt::format("stage 4: screening again with {} in the model{}", d.effect,
                      remaining.run ? "; the missing force left beside it" : ""));
      std::vector<const Candidate*> with = {&d.candidates[a.candidate]};
      std::vector<int> others;
      for (int c = 0; c < static_cast<int>(d.candidates.size()); ++c)
        if (c != a.candidate && d.candidates[c].screened) {
          with.push_back(&d.candidates[c]);
          others.push_back(c);
        }
      Model again = load_model(d.scenario, nominal, with, true,
                               (models / "screening-with-effect.yaml").string(), 0);
      const ParameterMap& amap = again.problem->map();
      const int n_fixed = static_cast<int>(a.p.size());
      bool same = amap.size() >= n_fixed;
      for (int j = 0; same && j < n_fixed; ++j) same = amap.label(j) == a.labels[j];
      if (!same) throw Error("internal: the second screening's parameters differ from the refit's");
      Eigen::VectorXd p2 = amap.initial();
      p2.head(n_fixed) = a.p;
      const GaussNewtonSystem g2 = screening_system(
          again, d.scenario, nominal, with, 0, p2, models, "screening-with-effect", o.interrupt,
          world(), remaining.run ? &remaining : nullptr, &screening_costs);
      beside = static_cast<bool>(remaining.run);
      if (g2.ok) {
        std::vector<std::pair<std::string, std::vector<int>>> groups2;
        ScreeningOptions so2;
        so2.noise_variance = sigma2;
        so2.held = unresolved_entries(amap, p2, g2.jacobian, std::sqrt(sigma2), range(n_fixed));
        const Eigen::VectorXd lo2 = amap.lower(), start2 = amap.initial();
        for (std::size_t k = 0; k < others.size(); ++k) {
          const std::vector<int> e = entries_of(again, again.extended.candidate_specs[k + 1]);
          groups2.emplace_back(slug(d.candidates[others[k]]), e);
          for (int j : e)
            if (lo2[j] == start2[j]) so2.nonnegative.push_back(j);
        }
        d.second_ranking = rank_candidates(g2.residual, g2.jacobian, range(n_fixed), groups2, so2,
                                           d.settings.alpha);
        if (!d.second_ranking.order.empty() && d.second_ranking.order[0].significant) {
          const RankedCandidate& top = d.second_ranking.order[0];
          Candidate& second = d.candidates[others[top.candidate]];
          d.second_candidate = others[top.candidate];
          // Its refit starts from its screening step here, as the first stage's do;
          // one screened as alternatives takes the one that explains most here.
          const std::vector<int> group = groups2[top.candidate].second;
          const CandidateScore score =
              second.alternatives ? chosen_alternative(g2, n_fixed, group, so2, amap, second.choice)
                                  : top.marginal;
          second_start = [&, score, group, alternatives = second.alternatives](
                             Model& model, const std::vector<int>& entries) {
            return start_from_score(model.problem->map(), a.p, score, alternatives, group, entries);
          };
        }
        for (auto& rc : d.second_ranking.order) rc.candidate = others[rc.candidate];
        for (auto& c : d.second_ranking.confounded) {
          c.a = others[c.a];
          c.b = others[c.b];
        }
        for (const auto& rc : d.second_ranking.order)
          say(fmt::format("  {:<22} LM {:10.1f}  (threshold {:7.1f}){}",
                          slug(d.candidates[rc.candidate]), rc.marginal.statistic, rc.threshold,
                          rc.significant ? "  significant" : ""));
      } else {
        say(fmt::format("  the second screening failed: {}", g2.error));
      }
      d.seconds.second_screening = since(t0);
    }
    if (remaining.run && !beside && !stopped()) {
      say(fmt::format("stage 4: the missing force left with {} in the model", d.effect));
      remaining.result = spread_tasks(world(), 1, remaining.run, o.progress, o.interrupt)[0];
    }
    if (!remaining.result.empty()) {
      d.remaining_force = unpacked_force(remaining.result);
      d.seconds.missing_force += d.remaining_force.seconds;
      // On one rank the field's fit ran within the stage's time.
      if (beside && world().size() == 1) d.seconds.second_screening -= d.remaining_force.seconds;
    }
    if (accepted && remaining.result.empty())  // (else its task said it)
      say("  missing force left: " + describe(d.remaining_force));
    // A second effect is named as the first was: by its refit, with the first at its
    // refit and every parameter free, judged against that model on the training data
    // and the held-out motions (a score alone also flags what the first refit left of
    // the model error: V09's added mass at LM 21.1 of 17.4).
    if (d.second_candidate >= 0 && second_start && !stopped()) {
      RefitBase first;
      first.with = {&d.candidates[a.candidate]};
      first.p = a.p;
      first.train = &a.train;
      for (const HeldOutFigures& h : a.heldout) {
        HeldOutFigures f = h;  // a motion the first refit could not run is not judged
        f.before = h.after;
        f.after = MisfitFigures();
        first.heldout.push_back(std::move(f));
      }
      first.tests = static_cast<int>(d.second_ranking.order.size());
      first.prefix = slug(d.candidates[a.candidate]) + "+";
      first.on_top_of = a.candidate;
      first.name = slug(d.candidates[a.candidate]) + "'s refit";
      const int c = d.second_candidate;
      say(fmt::format("stage 4: refit of {} with {} in the model", slug(d.candidates[c]),
                      d.effect));
      if (auto res = gathered_refit(spread_tasks(
                                        world(), 1,
                                        [&](int, const ProgressLine& line) {
                                          return refit_task(c, second_start, line, first);
                                        },
                                        o.progress, o.interrupt)[0],
                                    d.seconds.refits, first))
        d.second_refit = std::move(*res);
      if (d.second_refit.candidate == c && passes(d.second_refit)) {
        d.second_effect = d.candidates[c].id;
        d.fitted_yaml = d.second_refit.fitted_yaml;
        // (after the first effect's place, which every accepted effect has: its own
        // or the region whose markers carry most of the residual)
        if (!d.verdict_where.empty() && !d.second_refit.where.empty())
          d.verdict_where.push_back(d.second_refit.where);
        say(fmt::format("  second effect: {}", slug(d.candidates[c])));
      }
    }
  } else {
    // The nominal model is the answer: its fitted scenario is the one to run.
    d.fitted_yaml = on_root([&] {
      FemModel& model = base.problem->experiment(0).model();
      base_map.apply(p_nominal, model);
      return write_fitted_scenario(*base.scenario, base_map, model, (out / "nominal").string());
    });
  }
  d.interrupted = stopped();
  return d;
}

}  // namespace kelvin
