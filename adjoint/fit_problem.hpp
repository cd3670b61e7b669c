#pragma once
/// \file
/// Φ(p) and dΦ/dp over every experiment of a fit: the main scenario and the
/// further captured motions listed in its `fit.experiments`, all sharing one
/// parameter map (the same specimen in different motions; Φ is their sum).
#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "adjoint/experiment.hpp"
#include "adjoint/parameter_map.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {

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
  double seconds = 0;
};

class FitProblem {
 public:
  /// Loads the experiments of `scenario.fit.experiments` (paths relative to the
  /// scenario) and builds the map of `specs` (default_fit_parameters when empty).
  /// The scenario must outlive the problem (a temporary would not).
  FitProblem(const Scenario& scenario, std::vector<FitParameterSpec> specs = {});
  FitProblem(Scenario&&, std::vector<FitParameterSpec> = {}) = delete;

  const ParameterMap& map() const { return *map_; }
  int num_experiments() const { return static_cast<int>(experiments_.size()); }
  Experiment& experiment(int i) { return *experiments_[i]; }

  Evaluation evaluate(const Eigen::VectorXd& p, const GradientOptions& options);

 private:
  std::vector<std::unique_ptr<Scenario>> owned_;  // experiments loaded here
  std::vector<std::unique_ptr<Experiment>> experiments_;
  std::unique_ptr<ParameterMap> map_;
};

}  // namespace kelvin
