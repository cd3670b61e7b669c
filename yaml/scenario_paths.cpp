#include "yaml/scenario_paths.hpp"

#include <filesystem>

namespace kelvin {
namespace {

namespace fs = std::filesystem;

void make_absolute(YAML::Node node, const yamlutil::Doc& d) {
  if (node.IsDefined() && node.IsScalar())
    node = fs::absolute(d.resolve(node.Scalar())).lexically_normal().string();
}

}  // namespace

void absolute_scenario_paths(const YAML::Node& root, const yamlutil::Doc& d) {
  make_absolute(yaml_child(yaml_child(root, "mesh"), "file"), d);
  const YAML::Node material = yaml_child(root, "material");
  make_absolute(yaml_child(material, "fields"), d);
  for (const char* kind : {"elastic", "viscous"}) {
    const YAML::Node terms = yaml_child(material, kind);
    if (terms.IsDefined() && terms.IsSequence())
      for (const auto& term : terms) make_absolute(yaml_child(term, "plugin"), d);
    else
      make_absolute(yaml_child(terms, "plugin"), d);
  }
  if (const YAML::Node clamps = yaml_child(root, "clamps");
      clamps.IsDefined() && clamps.IsSequence())
    for (const auto& clamp : clamps)
      make_absolute(yaml_child(yaml_child(clamp, "motion"), "file"), d);
  const YAML::Node markers = yaml_child(root, "markers");
  make_absolute(yaml_child(markers, "rest"), d);  // a list of inline markers stays as it is
  make_absolute(yaml_child(markers, "observed"), d);
  if (const YAML::Node experiments = yaml_child(yaml_child(root, "fit"), "experiments");
      experiments.IsDefined() && experiments.IsSequence())
    for (const auto& e : experiments) make_absolute(e, d);
  if (const YAML::Node measurements = yaml_child(yaml_child(root, "probing"), "measurements");
      measurements.IsDefined() && measurements.IsSequence())
    for (const auto& m : measurements) make_absolute(yaml_child(m, "observed"), d);
}

YAML::Node yaml_child(const YAML::Node& node, const std::string& key) {
  return node.IsDefined() && node.IsMap() ? node[key] : YAML::Node(YAML::NodeType::Undefined);
}

}  // namespace kelvin
