#include "adjoint/fit_problem.hpp"

#include <fmt/format.h>

#include <chrono>
#include <filesystem>
#include <numeric>

#include "adjoint/result_exchange.hpp"
#include "base/error.hpp"
#include "materials/material.hpp"
#include "probing/probe_experiment.hpp"

namespace kelvin {

std::vector<FitParameterSpec> default_fit_parameters(const Scenario& s) {
  std::vector<FitParameterSpec> out;
  for (const MaterialQuantity& q : material_quantities(s.material)) {
    if (q.term < 0) continue;  // the density is fitted only when asked for
    FitParameterSpec spec;
    spec.target = q.name;
    spec.lower = q.info.lower;
    spec.upper = q.info.upper;
    spec.log = q.info.positive;
    // Parameters at zero (e.g. an unused Rayleigh coefficient) cannot start a log fit.
    if (spec.log && !(q.value > 0)) continue;
    out.push_back(spec);
  }
  return out;
}

FitProblem::FitProblem(const Scenario& scenario, std::vector<FitParameterSpec> specs,
                       Communicator& comm)
    : comm_(&comm) {
  if (specs.empty()) specs = default_fit_parameters(scenario);
  scenario_ = &scenario;
  // A scenario of static measurements alone is fitted to them; one with captured
  // tracks too to both.
  const bool probed = has_probing(scenario);
  if (!probed || !scenario.markers.observed.names.empty() ||
      !scenario.fit.objective.targets.empty())
    experiments_.push_back(std::make_unique<Experiment>(scenario, scenario.fit.objective));
  if (probed) add_static_terms(scenario);
  const auto dir = std::filesystem::path(scenario.path).parent_path();
  for (const auto& file : scenario.fit.experiments) {
    owned_.push_back(std::make_unique<Scenario>(load_scenario((dir / file).string())));
    const Scenario& other = *owned_.back();
    if (other.mesh.num_tets() != scenario.mesh.num_tets() ||
        other.mesh.num_nodes() != scenario.mesh.num_nodes())
      throw Error(fmt::format(
          "{}: fit.experiments: {} has a different mesh ({} tets) than {} ({} tets); the "
          "experiments of one fit share the specimen's mesh",
          scenario.path, other.path, other.mesh.num_tets(), scenario.path,
          scenario.mesh.num_tets()));
    // A probing scenario adds its static measurements, and its captured motion when it
    // has one too.
    // The marker weights and window are the fit's; shape targets belong to the
    // motion whose file states them.
    ObjectiveSpec objective = scenario.fit.objective;
    objective.targets = other.fit.objective.targets;
    const bool probing = has_probing(other);
    if (!probing || !other.markers.observed.names.empty() || !objective.targets.empty())
      experiments_.push_back(std::make_unique<Experiment>(other, objective));
    if (probing) add_static_terms(other);
  }
  if (experiments_.empty() && statics_.empty())
    throw Error(fmt::format(
        "{}: nothing to fit: no observed tracks (markers.observed) and no static measurement "
        "with observed positions (probing.measurements[].observed)",
        scenario.path));
  weigh_static_terms(scenario);
  plans_.resize(experiments_.size());
  map_ = std::make_unique<ParameterMap>(
      specs, scenario, model(),
      experiments_.empty() ? std::vector<std::string>{} : experiments_[0]->objective().names());
  // Joint experiments share the fitted parameters, so each must have the same
  // material models; otherwise a slot would name another model's parameter (found
  // here, not as a failed simulation at the first evaluation).
  if (experiments_.size() > 1 && map_->has_body_force())
    throw Error(fmt::format(
        "{}: fit.experiments: a body force (body_force.x|y|z) explains one motion; fit it on "
        "one experiment, not jointly with {}",
        scenario.path, experiments_[1]->scenario().path));
  for (const ParamSlot& slot : map_->slots())
    if (!statics_.empty() && (slot.is_clamp() || slot.is_force()))
      throw Error(fmt::format(
          "{}: fit.parameters: clamp compliances and body forces belong to one captured motion; "
          "a fit with static measurements ({}) cannot carry them",
          scenario.path, statics_[0]->name()));
  if (!statics_.empty() && !map_->observation_blocks().empty())
    throw Error(fmt::format(
        "{}: fit.parameters: markers.* parameters belong to captured tracks; a fit with static "
        "measurements ({}) cannot carry them yet",
        scenario.path, statics_[0]->name()));
  for (const auto& st : statics_) {
    const auto& mine = model().terms();
    const auto& theirs = st->model().terms();
    bool same = mine.size() == theirs.size();
    for (size_t k = 0; same && k < mine.size(); ++k)
      same = mine[k].model->name() == theirs[k].model->name();
    if (!same)
      throw Error(fmt::format(
          "{}: fit.experiments: static measurement '{}' has other material models than {}; "
          "experiments fitted jointly share the fitted parameters",
          scenario.path, st->name(), scenario.path));
  }
  const auto& terms = model().terms();
  for (size_t e = 1; e < experiments_.size(); ++e) {
    const auto& other = experiments_[e]->model().terms();
    for (const ParamSlot& slot : map_->slots()) {
      if (slot.is_clamp()) {
        const auto& mine = experiments_[0]->model().clamps()[slot.clamp];
        const auto& clamps = experiments_[e]->model().clamps();
        if (slot.clamp >= static_cast<int>(clamps.size()) || clamps[slot.clamp].name != mine.name ||
            !clamps[slot.clamp].compliant())
          throw Error(fmt::format(
              "{}: fit.experiments: {} fits the compliance of clamp '{}', which {} does not "
              "have as its clamp {} with a compliance; experiments fitted jointly share the "
              "fitted parameters",
              scenario.path, scenario.path, mine.name, experiments_[e]->scenario().path,
              slot.clamp));
        continue;
      }
      if (slot.is_density()) continue;
      const std::string mine = terms[slot.term].model->name();
      const std::string theirs =
          slot.term < static_cast<int>(other.size()) ? other[slot.term].model->name() : "none";
      if (mine != theirs)
        throw Error(fmt::format(
            "{}: fit.experiments: {}'s {} material model is '{}', {}'s is '{}'; experiments "
            "fitted jointly share the fitted parameters, so they need the same material models",
            scenario.path, experiments_[e]->scenario().path, slot.term == 0 ? "elastic" : "viscous",
            theirs, scenario.path, mine));
    }
  }
}

FitProblem::~FitProblem() = default;

FemModel& FitProblem::model() {
  return experiments_.empty() ? statics_[0]->model() : experiments_[0]->model();
}

void FitProblem::add_static_terms(const Scenario& probing) {
  const ProbingSpec spec = load_probing(probing);
  probes_.push_back(std::make_unique<ProbeExperiment>(probing, spec));
  ProbeExperiment& ex = *probes_.back();
  // A measurement without observed positions (one kept for kelvin probe's
  // predictions), or with every marker occluded, tells the fit nothing.
  for (int m = 0; m < ex.size(); ++m)
    if (spec.measurements[m].observed.array().isFinite().any() || !ex.measured_reactions(m).empty())
      statics_.push_back(std::make_unique<StaticTerm>(
          ex.model(m), spec.measurements[m].name, ex.scenario().markers.embedded,
          spec.measurements[m].observed, spec.weight, ex.measured_reactions(m),
          spec.reaction_weight()));
}

void FitProblem::weigh_static_terms(const Scenario& main) {
  // Each measurement weighs like a captured track as long as the fitted one (alone,
  // any weight is the same fit), unless its probing section says otherwise.
  const double fallback = experiments_.empty() || !(main.time.end > 0) ? 1.0 : main.time.end;
  for (auto& st : statics_)
    if (!(st->weight() > 0)) st->set_weight(fallback);
}

namespace {

/// What rank `from` sends after its share of an evaluation: whether it was
/// interrupted, the message of an exception it met, and the result and plan of each
/// experiment it owns.
std::string pack_share(const FitProblem& problem, const std::vector<ExperimentResult>& results,
                       const std::vector<EvaluationPlan>& plans, bool interrupted,
                       const std::string& thrown) {
  ByteWriter out;
  out.put(interrupted);
  out.put(thrown);
  for (size_t i = 0; i < results.size(); ++i)
    if (problem.owns(static_cast<int>(i))) {
      put(out, results[i]);
      put(out, plans[i]);
    }
  return out.bytes();
}

}  // namespace

int FitProblem::owner(int experiment) const {
  return owners_.empty() ? experiment % comm_->size() : owners_[experiment];
}

void FitProblem::balance(const std::vector<ExperimentResult>& results, double tolerance_scale) {
  // Motions differ in cost (the bench's four at 17–29 Hz: round robin gave 1.69× on
  // two ranks). Balanced once per tolerance scale: a stage's costs are alike.
  if (tolerance_scale == balanced_scale_ || static_cast<int>(results.size()) <= comm_->size())
    return;
  for (const ExperimentResult& r : results)
    if (!r.ok) return;
  std::vector<int> order(results.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return results[a].seconds > results[b].seconds; });
  std::vector<double> load(comm_->size(), 0.0);
  owners_.assign(results.size(), 0);
  for (int i : order) {
    const int r = static_cast<int>(std::min_element(load.begin(), load.end()) - load.begin());
    owners_[i] = r;
    load[r] += results[i].seconds;
  }
  balanced_scale_ = tolerance_scale;
}

Evaluation FitProblem::evaluate(const Eigen::VectorXd& p, const GradientOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  Evaluation ev;
  ev.ok = true;
  std::vector<ExperimentResult> results(experiments_.size());
  std::exception_ptr thrown;
  try {
    for (size_t i = 0; i < experiments_.size(); ++i)
      if (owns(static_cast<int>(i)))
        results[i] = experiments_[i]->evaluate(*map_, p, options, plans_[i]);
  } catch (...) {
    thrown = std::current_exception();
  }
  ev.interrupted = options.interrupt && options.interrupt->load();
  if (comm_->size() > 1) {
    std::string message;
    if (thrown) try {
        std::rethrow_exception(thrown);
      } catch (const std::exception& e) {
        message = e.what();
      } catch (...) {
        message = "an unknown exception";
      }
    const std::vector<std::string> shares =
        comm_->all_gather(pack_share(*this, results, plans_, ev.interrupted, message));
    std::string first_thrown;
    for (int r = 0; r < comm_->size(); ++r) {
      ByteReader in(shares[r]);
      bool interrupted = false;
      std::string m;
      in.get(interrupted);
      in.get(m);
      ev.interrupted = ev.interrupted || interrupted;
      if (first_thrown.empty()) first_thrown = m;
      for (size_t i = 0; i < experiments_.size(); ++i)
        if (owner(static_cast<int>(i)) == r) {
          get(in, results[i]);
          get(in, plans_[i]);
        }
      if (!in.done()) throw Error("internal: a rank's results were not read to their end");
    }
    if (ev.interrupted && !(options.interrupt && options.interrupt->load())) comm_->interrupt();
    if (!first_thrown.empty()) throw Error(first_thrown);
    balance(results, options.tolerance_scale);
  } else if (thrown) {
    std::rethrow_exception(thrown);
  }
  double weighted_time = 0;
  if (options.method != GradientMethod::kNone) ev.gradient.setZero(map_->size());
  for (size_t i = 0; i < experiments_.size(); ++i) {
    const auto& ex = experiments_[i];
    ExperimentResult& r = results[i];
    if (!r.ok && ev.ok) {
      ev.ok = false;
      // Name the experiment unless the message already does (static-state errors).
      ev.error = r.error.rfind(ex->scenario().path, 0) == 0
                     ? r.error
                     : fmt::format("{}: {}", ex->scenario().path, r.error);
    }
    ev.phi += r.phi;
    weighted_time += ex->objective_weight();
    if (r.ok && r.gradient.size()) ev.gradient += r.gradient;
    ev.experiments.push_back(std::move(r));
  }
  for (auto& st : statics_) {
    StaticTermResult r = st->evaluate(*map_, p, options.method != GradientMethod::kNone);
    if (!r.ok && ev.ok) ev.ok = false, ev.error = r.error;
    ev.phi += r.phi;
    // A measured reaction counts as one more marker: its residual is in units of
    // the marker noise (StaticTerm).
    weighted_time += st->weight() * (st->observed_markers() + st->measured_reactions());
    if (r.ok && r.gradient.size()) ev.gradient += r.gradient;
    ev.statics.push_back(std::move(r));
  }
  ev.rms = std::sqrt(2 * ev.phi / weighted_time);
  ev.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return ev;
}

}  // namespace kelvin
