#include "fit/fitted_scenario.hpp"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <filesystem>
#include <iterator>
#include <map>
#include <vector>

#include "engine/output.hpp"
#include "yaml/scenario_paths.hpp"
#include "yaml/yaml_util.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;

// 17 significant digits read back as the same double, so that simulating
// fitted.yaml reproduces the fitted model bit for bit.
std::string exact(double v) {
  return fmt::format("{:.17g}", v);
}

/// A column of fitted-fields.csv: a quantity taken from the model element by element.
struct Column {
  std::string target;
  int term = -1;  // −1 density, else FemModel::terms() index
  int index = 0;
};

double model_value(const FemModel& model, int term, int index, int e) {
  return term < 0 ? model.density()[e] : model.terms()[term].q(index, e);
}

/// The scalar the scenario gives for a quantity (before any substitution here).
double scenario_value(const Scenario& s, const FemModel& model, const Column& c) {
  if (c.term < 0) return s.material.density;
  return s.material.term(c.term).params.at(model.terms()[c.term].model->params()[c.index].name);
}

/// The node of term `term` (FemModel order) under `material`: the mapping itself for
/// a single term, its entry for a list.
YAML::Node term_node(YAML::Node material, const MaterialSpec& m, int term) {
  const bool viscous = term >= static_cast<int>(m.elastic.size());
  YAML::Node kind = material[viscous ? "viscous" : "elastic"];
  const int k = viscous ? term - static_cast<int>(m.elastic.size()) : term;
  return kind.IsSequence() ? kind[k] : kind;
}

/// Writes the scalar of a quantity into the `material` node.
void set_scalar(YAML::Node material, const Scenario& s, const FemModel& model, const Column& c,
                double v) {
  if (c.term < 0) {
    material["density"] = exact(v);
    return;
  }
  YAML::Node term = term_node(material, s.material, c.term);
  const MaterialTermSpec& spec = s.material.term(c.term);
  const std::string name = model.terms()[c.term].model->params()[c.index].name;
  // A λ or μ next to E and ν is refused by the loader, so the pair gives way to the
  // λ and μ it stood for.
  if ((name == "lambda" || name == "mu") && term["E"] && !spec.params.count("E")) {
    term.remove("E");
    term.remove("nu");
    term["lambda"] = exact(spec.params.at("lambda"));
    term["mu"] = exact(spec.params.at("mu"));
  }
  term[name] = exact(v);
}

}  // namespace

std::string write_fitted_scenario(const Scenario& scenario, const ParameterMap& map,
                                  const FemModel& model, const std::string& outdir,
                                  const Eigen::VectorXd& p) {
  const yamlutil::Doc doc(scenario.path);
  YAML::Node root = doc.root();  // a handle: edits change the document's tree
  absolute_scenario_paths(root, doc);
  YAML::Node material = yaml_child(root, "material");
  const int ne = model.mesh().num_tets();

  // The input's own fields stay in force, now with the model's values (which are the
  // file's where nothing was fitted).
  std::vector<Column> columns;
  for (const auto& f : scenario.material.fields) columns.push_back({f.target, f.term, f.index});
  std::map<std::string, double> scalar;  // target → value now in the `material` node
  for (const auto& b : map.blocks()) {
    // A fitted body force explains a motion, it is not a property of the specimen:
    // it goes to body-force.csv and its VTU series (body_force_outputs.hpp).
    if (b.slot.is_force()) continue;
    if (b.slot.is_clamp()) {
      // clamps[k] is the scenario's k-th entry; its compliance replaces either key.
      YAML::Node clamp = yaml_child(root, "clamps")[b.slot.clamp];
      clamp.remove("stiffness");
      clamp["compliance"] = exact(model.clamps()[b.slot.clamp].compliance);
      continue;
    }
    const Column c{b.target, b.slot.term, b.slot.index};
    if (!scalar.count(c.target)) scalar[c.target] = scenario_value(scenario, model, c);
    // A multiplier field is written as the field it made: the fit section's start (a
    // multiplier or coefficients) stays valid against any scalar.
    if (b.is_multiplier()) {
      if (std::none_of(columns.begin(), columns.end(),
                       [&](const Column& o) { return o.target == c.target; }))
        columns.push_back(c);
      continue;
    }
    const auto mapped = std::find_if(b.entry.begin(), b.entry.end(), [](int j) { return j >= 0; });
    if (mapped == b.entry.end()) continue;
    const int first = static_cast<int>(mapped - b.entry.begin());
    // exp(ln upper) may land an ulp outside the bounds; the fit section's start check
    // (which reads the scalar now that `initial` is gone) would then refuse the file.
    const double fitted = std::clamp(model_value(model, c.term, c.index, first), b.lower, b.upper);
    const bool global = b.count == 1 && !b.per_element &&
                        std::none_of(b.entry.begin(), b.entry.end(), [](int j) { return j < 0; });
    if (global) {
      scalar[c.target] = fitted;
      set_scalar(material, scenario, model, c, fitted);
      continue;
    }
    if (std::none_of(columns.begin(), columns.end(),
                     [&](const Column& o) { return o.target == c.target; }))
      columns.push_back(c);
    // The field overrides the scalar, but the fit section still checks it as a start.
    const double now = scalar[c.target];
    if (now < b.lower || now > b.upper || (b.log && now <= 0)) {
      scalar[c.target] = fitted;
      set_scalar(material, scenario, model, c, fitted);
    }
  }

  const fs::path dir(outdir);
  fs::create_directories(dir);
  if (columns.empty()) {
    material.remove("fields");
  } else {
    std::string csv = "element";
    for (const auto& c : columns) fmt::format_to(std::back_inserter(csv), ",{}", c.target);
    csv += '\n';
    for (int e = 0; e < ne; ++e) {
      fmt::format_to(std::back_inserter(csv), "{}", e);
      for (const auto& c : columns) {
        csv += ',';
        csv += exact(model_value(model, c.term, c.index, e));
      }
      csv += '\n';
    }
    // Before fitted.yaml, so that the scenario never names a file not yet there.
    write_file_atomic((dir / "fitted-fields.csv").string(), csv);
    material["fields"] = "fitted-fields.csv";
  }

  // The fitted values are now the scenario's, so a further fit starts from them.
  std::string observation;  // header lines of the fitted observation parameters
  if (YAML::Node params = yaml_child(yaml_child(root, "fit"), "parameters");
      params.IsDefined() && params.IsSequence()) {
    for (auto entry : params)
      if (entry.IsMap()) entry.remove("initial");
    // The observation parameters have no place in the model: a one-entry block (the
    // clock offset) starts a further fit where this one ended, and every block is
    // listed for people.
    if (p.size() == map.size())
      for (const ObservationBlock& o : map.observation_blocks()) {
        observation += fmt::format("#   {} =", o.target);
        for (int j = 0; j < o.count; ++j) observation += fmt::format(" {:.6g}", p[o.offset + j]);
        observation += "\n";
        if (o.count != 1) continue;
        for (std::size_t k = 0; k < params.size(); ++k) {
          YAML::Node entry = params[k];
          const bool named = entry.IsScalar() ? entry.as<std::string>() == o.target
                                              : entry.IsMap() && entry["target"] &&
                                                    entry["target"].as<std::string>() == o.target;
          if (!named) continue;
          if (entry.IsScalar()) {
            YAML::Node spelled;
            spelled["target"] = o.target;
            params[k] = spelled;
          }
          params[k]["initial"] = exact(p[o.offset]);
        }
      }
  }
  // Without a name the file's stem ("fitted") would rename the outputs.
  if (!yaml_child(root, "name")) root["name"] = scenario.name;

  YAML::Emitter out;
  out << root;
  const std::string input = fs::absolute(scenario.path).lexically_normal().string();
  const std::string path = (dir / "fitted.yaml").string();
  if (!observation.empty())
    observation = "# Fitted observation parameters (of the capture, not the model; SI units):\n" +
                  observation;
  write_file_atomic(path, fmt::format("# Written by kelvin fit from {}: that scenario with the "
                                      "fitted parameters substituted.\n{}{}\n",
                                      input, observation, out.c_str()));
  return path;
}

}  // namespace kelvin
