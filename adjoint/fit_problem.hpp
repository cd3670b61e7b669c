#pragma once
/// \file
/// Φ(p) and dΦ/dp over every experiment of a fit: the main scenario and the
/// further captured motions listed in its `fit.experiments`, all sharing one
/// parameter map (the same specimen in different motions; Φ is their sum). A
/// scenario of `fit.experiments` with a `probing:` section adds its static
/// measurements (StaticTerm): the specimen probed as well as shaken.
#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "adjoint/experiment.hpp"
#include "adjoint/parameter_map.hpp"
#include "adjoint/static_term.hpp"
#include "base/communicator.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {

class ProbeExperiment;

/// Every elastic and viscous parameter and nothing else, global, log-transformed
/// where the model declares it positive: the map used when a scenario has no
/// `fit.parameters`.
std::vector<FitParameterSpec> default_fit_parameters(const Scenario& scenario);

struct Evaluation {
  bool ok = false;
  std::string error;  // the first failing experiment's message
  double phi = 0;
  double rms = 0;            // over all experiments (m)
  Eigen::VectorXd gradient;  // dΦ/dp (empty without a gradient)
  std::vector<ExperimentResult> experiments;
  std::vector<StaticTermResult> statics;  // per static measurement
  double seconds = 0;
  /// Whether the run was interrupted by the end of this evaluation, on any rank: the
  /// value every rank acts on (a signal that lands on one rank later must not send
  /// it down another path).
  bool interrupted = false;
};

class FitProblem {
 public:
  /// Loads the experiments of `scenario.fit.experiments` (paths relative to the
  /// scenario) and builds the map of `specs` (default_fit_parameters when empty).
  /// Static measurements come from a `probing:` section of the scenario or of its
  /// experiments; a scenario without tracks is then fitted to them alone.
  /// The scenario must outlive the problem (a temporary would not).
  /// Experiments are spread over the ranks of `comm` (FitProblem::owner).
  FitProblem(const Scenario& scenario, std::vector<FitParameterSpec> specs = {},
             Communicator& comm = world());
  FitProblem(Scenario&&, std::vector<FitParameterSpec> = {}, Communicator& = world()) = delete;
  ~FitProblem();

  const ParameterMap& map() const { return *map_; }
  /// The fitted scenario, and the model the map was built on (the first captured
  /// motion's, or the first static measurement's when there is none): the one
  /// outputs write the fitted fields of.
  const Scenario& scenario() const { return *scenario_; }
  FemModel& model();
  const Mesh& mesh() const { return scenario_->mesh; }
  int num_experiments() const { return static_cast<int>(experiments_.size()); }
  Experiment& experiment(int i) { return *experiments_[i]; }
  /// How experiment i's evaluations integrate (EvaluationPlan): every evaluation of
  /// this problem, and every sampling of its tracks, goes by it.
  EvaluationPlan& plan(int i) { return plans_[i]; }
  int num_static_terms() const { return static_cast<int>(statics_.size()); }
  StaticTerm& static_term(int i) { return *statics_[i]; }

  /// Φ and, on request, dΦ/dp at p. Collective over the communicator: each rank
  /// simulates the experiments it owns, and every rank receives every result and
  /// plan, so that all hold what a serial evaluation would, to the bit (sums in
  /// experiment order). A failure on one rank is a failed evaluation on all; an
  /// exception on one is thrown on all. Static terms are evaluated on every rank.
  Evaluation evaluate(const Eigen::VectorXd& p, const GradientOptions& options);

  Communicator& communicator() const { return *comm_; }
  /// Evaluates on this rank alone from now on (rank 0 writing the outputs while
  /// the others have finished): the plans it holds are every experiment's.
  void evaluate_alone() {
    comm_ = &serial_communicator();
    owners_.clear();
  }
  /// The rank that simulates experiment i: i mod N until the first evaluation that
  /// succeeds at a tolerance scale, then the ranks balanced by the seconds each
  /// experiment took there (longest first, to the least loaded rank).
  int owner(int experiment) const;
  bool owns(int experiment) const { return owner(experiment) == comm_->rank(); }

 private:
  Communicator* comm_;
  std::vector<int> owners_;    // balanced owners (empty: i mod N)
  double balanced_scale_ = 0;  // the tolerance scale owners_ were balanced at
  /// Balances the owners by `results`' seconds, every rank alike (the seconds are shared).
  void balance(const std::vector<ExperimentResult>& results, double tolerance_scale);
  const Scenario* scenario_ = nullptr;
  std::vector<std::unique_ptr<Scenario>> owned_;  // experiments loaded here
  std::vector<std::unique_ptr<Experiment>> experiments_;
  std::vector<EvaluationPlan> plans_;                     // one per experiment
  std::vector<std::unique_ptr<ProbeExperiment>> probes_;  // the static terms' models
  std::vector<std::unique_ptr<StaticTerm>> statics_;
  std::unique_ptr<ParameterMap> map_;
  /// Adds the observed static measurements of `probing` (the fitted scenario or one
  /// of its fit.experiments).
  void add_static_terms(const Scenario& probing);
  /// Gives the static terms without a probing.weight the default one, once every
  /// experiment is loaded.
  void weigh_static_terms(const Scenario& main);
};

}  // namespace kelvin
