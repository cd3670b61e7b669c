#include "probing/probe_experiment.hpp"

#include <fmt/format.h>

#include "base/error.hpp"
#include "engine/clamp_reaction.hpp"
#include "yaml/scenario_simulation.hpp"

namespace kelvin {

ProbeExperiment::ProbeExperiment(const Scenario& scenario, const ProbingSpec& spec)
    : scenario_(scenario), spec_(spec) {
  const std::vector<LoadSpec> own = scenario_.loads;
  const std::vector<ClampSpec> supports = scenario_.clamps;
  for (const auto& m : spec_.measurements) {
    scenario_.loads = own;
    scenario_.loads.insert(scenario_.loads.end(), m.loads.begin(), m.loads.end());
    scenario_.clamps = supports;
    for (const auto& press : m.presses) scenario_.clamps.push_back(press.clamp);
    models_.push_back(build_model(scenario_));
  }
  scenario_.loads = own;
  scenario_.clamps = supports;
}

Eigen::Matrix3Xd ProbeExperiment::equilibrium(int m) {
  return static_equilibrium(*models_[m], spec_.measurements[m].name);
}

std::vector<Eigen::Vector3d> ProbeExperiment::reactions(int m, const Eigen::Matrix3Xd& x) {
  const FemModel& model = *models_[m];
  std::vector<Eigen::Vector3d> out;
  const int supports = static_cast<int>(scenario_.clamps.size());
  for (size_t k = 0; k < spec_.measurements[m].presses.size(); ++k) {
    const ClampReaction press(model, supports + static_cast<int>(k));
    Eigen::Vector3d R;
    if (!press.force(x, R))
      throw Error(fmt::format("measurement '{}': element {} is inadmissible at equilibrium",
                              spec_.measurements[m].name, press.failed_element));
    out.push_back(R);
  }
  return out;
}

std::vector<std::pair<int, Eigen::Vector3d>> ProbeExperiment::measured_reactions(int m) const {
  std::vector<std::pair<int, Eigen::Vector3d>> out;
  const auto& presses = spec_.measurements[m].presses;
  const int supports = static_cast<int>(scenario_.clamps.size());
  for (size_t k = 0; k < presses.size(); ++k)
    if (presses[k].reaction.allFinite())
      out.emplace_back(supports + static_cast<int>(k), presses[k].reaction);
  return out;
}

std::vector<ObservedProbe> ProbeExperiment::observed() {
  std::vector<ObservedProbe> out;
  for (int m = 0; m < size(); ++m)
    out.push_back({models_[m].get(), scenario_.markers.embedded, spec_.measurements[m].observed,
                   measured_reactions(m), spec_.reaction_weight()});
  return out;
}

std::vector<StaticState> ProbeExperiment::node_positions() {
  const Mesh& mesh = scenario_.mesh;
  const auto& markers = scenario_.markers.embedded;
  std::vector<StaticState> out;
  for (int m = 0; m < size(); ++m) {
    const FemModel& model = *models_[m];
    Eigen::VectorXd x_free = Eigen::VectorXd::Constant(model.num_dofs(), NAN);
    const Eigen::Matrix3Xd& seen = spec_.measurements[m].observed;
    for (size_t j = 0; j < markers.size(); ++j) {
      if (!seen.col(j).allFinite()) continue;
      for (int a = 0; a < 4; ++a) {
        if (markers[j].weights[a] < 1 - 1e-9) continue;
        const int node = mesh.tets(a, markers[j].tet);
        for (int i = 0; i < 3; ++i)
          if (model.dof(node, i) >= 0) x_free[model.dof(node, i)] = seen(i, j);
      }
    }
    for (int d = 0; d < x_free.size(); ++d)
      if (!std::isfinite(x_free[d]))
        for (int node = 0; node < mesh.num_nodes(); ++node)
          if (model.dof(node, d % 3) == d)
            throw Error(fmt::format(
                "measurement '{}': node {} at ({:.4g}, {:.4g}, {:.4g}) has no observed marker on "
                "it; the force-based inverse needs every unclamped node's position (use method: "
                "displacement)",
                spec_.measurements[m].name, node, mesh.nodes(0, node), mesh.nodes(1, node),
                mesh.nodes(2, node)));
    Eigen::Matrix3Xd x, v;
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(x_free.size());
    model.expand(0, x_free.data(), zero.data(), x, v);
    out.push_back({&model, x, measured_reactions(m)});
  }
  return out;
}

}  // namespace kelvin
