#pragma once
/// \file
/// A scenario's static measurements as models: one per measurement, under the
/// scenario's gravity and loads plus the probe's, all on the scenario's one mesh.
#include <memory>
#include <utility>
#include <vector>

#include "engine/fem_model.hpp"
#include "probing/displacement_inverse.hpp"
#include "probing/force_inverse.hpp"
#include "probing/probing_settings.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {

class ProbeExperiment {
 public:
  ProbeExperiment(const Scenario& scenario, const ProbingSpec& spec);
  ProbeExperiment(const ProbeExperiment&) = delete;  // the models refer to scenario_.mesh
  ProbeExperiment& operator=(const ProbeExperiment&) = delete;

  int size() const { return static_cast<int>(models_.size()); }
  const ProbingSpec& spec() const { return spec_; }
  const Scenario& scenario() const { return scenario_; }
  FemModel& model(int m) { return *models_[m]; }

  /// Every node's equilibrium position under measurement m at the models' current
  /// parameters; throws kelvin::Error naming the measurement when there is none.
  Eigen::Matrix3Xd equilibrium(int m);

  /// The force each of measurement m's pressed probes exerts on the body (N, `press`
  /// order) at its equilibrium positions x.
  std::vector<Eigen::Vector3d> reactions(int m, const Eigen::Matrix3Xd& x);
  /// The measurements as the displacement-based inverse takes them.
  std::vector<ObservedProbe> observed();
  /// As the force-based inverse takes them: every free node's position from a
  /// marker that sits on it; throws naming the first node without one.
  std::vector<StaticState> node_positions();

  /// Measurement m's pressed probes whose force was measured: (its model's clamp
  /// index, R̄ in N).
  std::vector<std::pair<int, Eigen::Vector3d>> measured_reactions(int m) const;

 private:
  Scenario scenario_;
  ProbingSpec spec_;
  std::vector<std::unique_ptr<FemModel>> models_;
};

}  // namespace kelvin
