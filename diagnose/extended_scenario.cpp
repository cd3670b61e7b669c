#include "diagnose/extended_scenario.hpp"

#include <fmt/format.h>

#include "adjoint/fit_problem.hpp"
#include "engine/output.hpp"
#include "yaml/scenario_paths.hpp"
#include "yaml/yaml_util.hpp"

namespace kelvin {
namespace {

/// A term list as a sequence (a single mapping becomes its only entry).
YAML::Node as_sequence(const YAML::Node& terms) {
  if (terms.IsDefined() && terms.IsSequence()) return YAML::Clone(terms);
  YAML::Node list(YAML::NodeType::Sequence);
  if (terms.IsDefined() && terms.IsMap()) list.push_back(YAML::Clone(terms));
  return list;
}

/// The nominal fit's parameter entries: the training file's own, or the defaults
/// (every material parameter) by name.
YAML::Node nominal_parameters(const Scenario& nominal) {
  const yamlutil::Doc doc(nominal.path);
  const YAML::Node given = yaml_child(yaml_child(doc.root(), "fit"), "parameters");
  if (given.IsDefined() && given.IsSequence()) return YAML::Clone(given);
  YAML::Node list(YAML::NodeType::Sequence);
  for (const auto& spec : default_fit_parameters(nominal)) list.push_back(spec.target);
  return list;
}

}  // namespace

ExtendedScenario write_extended_scenario(const std::string& source, const Scenario& nominal,
                                         const std::vector<const Candidate*>& candidates,
                                         bool screening, const std::string& path, int refit_form) {
  const yamlutil::Doc doc(source);
  YAML::Node root = YAML::Clone(doc.root());
  absolute_scenario_paths(root, doc);
  root.remove("diagnose");
  YAML::Node material = root["material"];
  ModelEdits lists;
  lists.elastic = as_sequence(yaml_child(material, "elastic"));
  lists.viscous = as_sequence(yaml_child(material, "viscous"));
  lists.clamps = root["clamps"];
  lists.root = root;
  lists.spec = &nominal.material;

  ExtendedScenario out;
  out.path = path;
  YAML::Node params = nominal_parameters(nominal);
  out.nominal_specs = static_cast<int>(params.size());
  for (std::size_t k = 0; k < candidates.size(); ++k) {
    const Candidate* c = candidates[k];
    const int before = static_cast<int>(params.size());
    c->extend(*c, lists, params, screening && static_cast<int>(k) != refit_form);
    std::vector<int> specs;
    for (int k = before; k < static_cast<int>(params.size()); ++k) specs.push_back(k);
    out.candidate_specs.push_back(specs);
  }
  material["elastic"] = lists.elastic;
  if (lists.viscous.size() > 0) material["viscous"] = lists.viscous;

  // The training file's fit settings (algorithm, limits, objective) hold for every
  // model of the diagnosis; its further experiments are extended alike.
  YAML::Node fit;
  if (source == nominal.path) {
    fit = yaml_child(root, "fit");
    if (const YAML::Node ex = yaml_child(fit, "experiments"); ex.IsDefined() && ex.IsSequence())
      for (std::size_t i = 0; i < ex.size(); ++i)
        fit["experiments"][i] =
            write_extended_scenario(ex[i].Scalar(), nominal, candidates, screening,
                                    fmt::format("{}.experiment{}.yaml", path, i), refit_form)
                .path;
  } else {
    const yamlutil::Doc training(nominal.path);
    YAML::Node training_root = YAML::Clone(training.root());
    absolute_scenario_paths(training_root, training);
    fit = yaml_child(training_root, "fit");
  }
  fit = fit.IsDefined() && fit.IsMap() ? YAML::Clone(fit) : YAML::Node(YAML::NodeType::Map);
  if (source != nominal.path) fit.remove("experiments");
  fit["parameters"] = params;
  // One stage at the scenario's tolerances: on a lightly damped body a looser stage's
  // integration error (0.6 mm at rtol 1e-3 on the diagnosis bars) exceeds the noise.
  fit["start_rtol"] = nominal.solver.rtol;
  root["fit"] = fit;
  if (!yaml_child(root, "name")) root["name"] = nominal.name;

  YAML::Emitter e;
  e << root;
  write_file_atomic(path,
                    fmt::format("# Written by kelvin diagnose from {}.\n{}\n", source, e.c_str()));
  return out;
}

}  // namespace kelvin
