#pragma once
// The sections of a scenario file, each read and validated on its own (internal to
// the loader; the public contract is yaml/scenario.hpp).
#include <yaml-cpp/yaml.h>

#include <vector>

#include "yaml/scenario.hpp"
#include "yaml/yaml_util.hpp"

namespace kelvin::scenario_detail {

MaterialSpec load_material(const yamlutil::Doc& d, const YAML::Node& node);
Mesh load_mesh(const yamlutil::Doc& d, const YAML::Node& node);
std::vector<ClampSpec> load_clamps(const yamlutil::Doc& d, const YAML::Node& node, const Mesh& mesh,
                                   const TimeSpec& time);
/// The `loads:` section; needs the clamps, whose nodes carry no load.
std::vector<LoadSpec> load_loads(const yamlutil::Doc& d, const YAML::Node& node, const Mesh& mesh,
                                 const std::vector<ClampSpec>& clamps);
/// A static measurement's `press:` list at path P (probes pressed to a depth); their
/// nodes may be held by no clamp nor other press.
std::vector<PressSpec> load_presses(const yamlutil::Doc& d, const YAML::Node& node,
                                    const std::string& P, const Mesh& mesh,
                                    const std::vector<ClampSpec>& clamps);
/// An entry's `select` at path P, parsed and resolved to at least one node of the mesh.
void select_entry_nodes(const yamlutil::Doc& d, const YAML::Node& entry, const std::string& P,
                        const Mesh& mesh, NodeSelection& selection, std::vector<int>& nodes);
MarkersSpec load_markers(const yamlutil::Doc& d, const YAML::Node& node, const Mesh& mesh);
/// The `fit:` section, checked against the rest of the scenario (material, markers, time).
FitSpec load_fit(const yamlutil::Doc& d, const YAML::Node& node, const Scenario& s);

}  // namespace kelvin::scenario_detail
