#include "probing/probing_settings.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>

#include "base/error.hpp"
#include "yaml/scenario_sections.hpp"
#include "yaml/yaml_util.hpp"

namespace kelvin {

using yamlutil::index;
using yamlutil::join;

bool has_probing(const Scenario& s) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(s.path, ec)) return false;  // built in memory
  const yamlutil::Doc d(s.path);
  return d.root().IsMap() && d.root()["probing"];
}

ProbingSpec load_probing(const Scenario& s) {
  const yamlutil::Doc d(s.path);
  const YAML::Node root = d.required(d.root(), "", "probing");
  const std::string P = "probing";
  d.require_map(root, P);
  d.check_keys(
      root, P,
      {"measurements", "method", "grouping", "gamma", "gamma_measurements", "weight", "noise"});
  ProbingSpec spec;
  if (const YAML::Node n = root["method"])
    spec.method = d.choice(n, join(P, "method"), {"displacement", "force"});
  if (const YAML::Node n = root["grouping"]) {
    const std::string g = d.choice(n, join(P, "grouping"), {"global", "region", "element"});
    spec.grouping = g == "global"   ? ElementGrouping::kGlobal
                    : g == "region" ? ElementGrouping::kRegion
                                    : ElementGrouping::kElement;
  }
  if (const YAML::Node n = root["gamma"]) spec.gamma = d.non_negative(n, join(P, "gamma"), "");
  if (const YAML::Node n = root["gamma_measurements"])
    spec.gamma_measurements = d.non_negative(n, join(P, "gamma_measurements"), "");
  if (const YAML::Node n = root["weight"]) spec.weight = d.positive(n, join(P, "weight"), "s");
  if (const YAML::Node n = root["noise"]) {
    const std::string NP = join(P, "noise");
    d.require_map(n, NP);
    d.check_keys(n, NP, {"markers", "force"});
    spec.marker_noise = d.positive(d.required(n, NP, "markers"), join(NP, "markers"), "m");
    spec.force_noise = d.positive(d.required(n, NP, "force"), join(NP, "force"), "N");
  }
  const YAML::Node ms = d.required(root, P, "measurements");
  d.require_sequence(ms, join(P, "measurements"));
  if (ms.size() == 0) d.fail(ms, join(P, "measurements"), "needs at least one measurement");
  const auto& markers = s.markers.embedded;
  for (size_t i = 0; i < ms.size(); ++i) {
    const YAML::Node m = ms[i];
    const std::string MP = index(join(P, "measurements"), i);
    d.require_map(m, MP);
    d.check_keys(m, MP, {"name", "loads", "press", "observed"});
    ProbeMeasurementSpec pm;
    pm.name = d.string(d.required(m, MP, "name"), join(MP, "name"));
    for (const auto& other : spec.measurements)
      if (other.name == pm.name)
        d.fail(m["name"], join(MP, "name"),
               fmt::format("'{}' is taken by an earlier one", pm.name));
    if (!m["loads"] && !m["press"])
      d.fail(m, MP, "give the probe as 'loads' (a force) or 'press' (a displacement), or both");
    if (const YAML::Node p = m["press"])
      pm.presses = scenario_detail::load_presses(d, p, join(MP, "press"), s.mesh, s.clamps);
    std::vector<ClampSpec> held = s.clamps;
    for (const auto& press : pm.presses) held.push_back(press.clamp);
    if (const YAML::Node l = m["loads"]) pm.loads = scenario_detail::load_loads(d, l, s.mesh, held);
    // A held node carries no load: a load under a press would move to its other nodes.
    std::vector<const LoadSpec*> loads;
    for (const auto& l : s.loads) loads.push_back(&l);
    for (const auto& l : pm.loads) loads.push_back(&l);
    for (size_t k = 0; k < pm.presses.size(); ++k)
      for (const LoadSpec* l : loads)
        for (int node : l->nodes)
          if (std::count(pm.presses[k].clamp.nodes.begin(), pm.presses[k].clamp.nodes.end(), node))
            d.fail(m["press"][k]["select"], join(index(join(MP, "press"), k), "select"),
                   fmt::format("node {} carries load '{}'; a pressed node is held and carries "
                               "none (select the load's nodes apart from the press's)",
                               node, l->name));
    for (size_t k = 0; k < pm.presses.size(); ++k)
      if (pm.presses[k].reaction.allFinite() && spec.force_noise < 0)
        d.fail(m["press"][k]["reaction"], join(index(join(MP, "press"), k), "reaction"),
               "a measured reaction needs probing.noise (markers: m, force: N) to weigh it "
               "against the markers");
    pm.observed =
        Eigen::Matrix3Xd::Constant(3, markers.size(), std::numeric_limits<double>::quiet_NaN());
    if (const YAML::Node o = m["observed"]) {
      if (markers.empty())
        d.fail(o, join(MP, "observed"), "needs the scenario's markers (markers.rest)");
      pm.observed_path = d.existing_file(o, join(MP, "observed"));
      MarkerRest rest;
      try {
        rest = read_marker_rest(pm.observed_path);
      } catch (const Error& e) {
        d.fail(o, join(MP, "observed"), e.what());
      }
      for (size_t j = 0; j < rest.names.size(); ++j) {
        const auto it = std::find_if(markers.begin(), markers.end(), [&](const MarkerEmbedding& k) {
          return k.name == rest.names[j];
        });
        if (it == markers.end())
          d.fail(o, join(MP, "observed"),
                 fmt::format("{}: marker '{}' is not one of markers.rest", pm.observed_path,
                             rest.names[j]));
        pm.observed.col(it - markers.begin()) = rest.positions.col(j);
      }
    }
    spec.measurements.push_back(std::move(pm));
  }
  return spec;
}

}  // namespace kelvin
