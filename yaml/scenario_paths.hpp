#pragma once
/// \file
/// The path-valued keys of a scenario (yaml/SCHEMA.md), made absolute in its YAML
/// tree: a scenario written elsewhere (fitted.yaml, a diagnosis's extended models)
/// must still find its mesh, motions and tracks.
#include <yaml-cpp/yaml.h>

#include "yaml/yaml_util.hpp"

namespace kelvin {

/// The child `key` of a mapping, or an undefined node. A non-const lookup would turn
/// a null value (`clamps:` with nothing after it) into a mapping, and asking a
/// missing key's node for its type throws.
YAML::Node yaml_child(const YAML::Node& node, const std::string& key);

/// Every path-valued key under `root` resolved against the document's directory.
void absolute_scenario_paths(const YAML::Node& root, const yamlutil::Doc& d);

}  // namespace kelvin
