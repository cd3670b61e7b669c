#include "diagnose/diagnose_settings.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <filesystem>

#include "diagnose/candidates.hpp"
#include "yaml/yaml_util.hpp"

namespace kelvin {

using yamlutil::join;

namespace {

/// An integer in [lo, hi], refused with its place otherwise.
int bounded_integer(const yamlutil::Doc& d, const YAML::Node& n, const std::string& path, long lo,
                    long hi) {
  const long v = d.integer(n, path);
  if (v < lo || v > hi) d.fail(n, path, fmt::format("must be in [{}, {}] (got {})", lo, hi, v));
  return static_cast<int>(v);
}

/// One entry of diagnose.custom, checked as far as it can be without the model: its
/// parameters are checked when the first extended model is loaded (diagnosis.cpp).
CustomCandidateSpec custom_candidate(const yamlutil::Doc& d, const YAML::Node& n,
                                     const std::string& P, const std::vector<std::string>& taken) {
  d.require_map(n, P);
  d.check_keys(n, P, {"id", "description", "where", "elastic", "viscous", "parameters"});
  CustomCandidateSpec c;
  const YAML::Node id = d.required(n, P, "id");
  c.id = d.string(id, join(P, "id"));
  const bool word = !c.id.empty() && std::islower(static_cast<unsigned char>(c.id[0])) &&
                    std::all_of(c.id.begin(), c.id.end(), [](char ch) {
                      return std::islower(static_cast<unsigned char>(ch)) ||
                             std::isdigit(static_cast<unsigned char>(ch)) || ch == '_';
                    });
  if (!word)
    d.fail(id, join(P, "id"),
           fmt::format("'{}' is not an identifier (lower-case letters, digits and _, from a "
                       "letter): it names the effect in diagnosis.json",
                       c.id));
  if (std::find(taken.begin(), taken.end(), c.id) != taken.end())
    d.fail(id, join(P, "id"),
           fmt::format("'{}' is taken (a built-in or an earlier candidate)", c.id));
  if (const YAML::Node v = n["description"]) c.description = d.string(v, join(P, "description"));
  if (const YAML::Node v = n["where"]) c.where = d.string(v, join(P, "where"));
  for (const char* kind : {"elastic", "viscous"}) {
    const YAML::Node t = n[kind];
    if (!t) continue;
    if (!c.kind.empty())
      d.fail(t, join(P, kind), "a custom candidate adds one term: elastic or viscous, not both");
    d.require_map(t, join(P, kind));
    d.required(t, join(P, kind), "model");
    c.kind = kind;
    c.term = YAML::Clone(t);
    if (const YAML::Node plugin = t["plugin"])
      c.term["plugin"] = d.resolve(d.string(plugin, join(join(P, kind), "plugin")));
  }
  const YAML::Node params = d.required(n, P, "parameters");
  d.require_sequence(params, join(P, "parameters"));
  if (params.size() == 0)
    d.fail(params, join(P, "parameters"), "is empty: the effect needs a parameter to fit");
  for (std::size_t i = 0; i < params.size(); ++i) {
    const std::string key = yamlutil::index(join(P, "parameters"), i);
    d.require_map(params[i], key);
    const std::string target = d.string(d.required(params[i], key, "target"), join(key, "target"));
    if (target.rfind("term.", 0) == 0 && c.kind.empty())
      d.fail(params[i]["target"], join(key, "target"),
             "names the candidate's term, but it adds none (elastic: or viscous:)");
  }
  c.parameters = YAML::Clone(params);
  const YAML::Mark at = n.Mark();
  c.place = fmt::format("{}:{}:{}: {}", d.file(), at.line + 1, at.column + 1, P);
  return c;
}

}  // namespace

DiagnoseSettings load_diagnose_settings(const std::string& path) {
  const yamlutil::Doc d(path);
  DiagnoseSettings s;
  const YAML::Node n = d.root()["diagnose"];
  if (!n || n.IsNull()) return s;
  const std::string P = "diagnose";
  d.require_map(n, P);
  d.check_keys(n, P,
               {"candidates", "exclude", "custom", "refits", "refit_evaluations", "significance",
                "validate", "missing_force"});
  std::vector<std::string> known = candidate_ids();
  if (const YAML::Node c = n["custom"]) {
    d.require_sequence(c, join(P, "custom"));
    for (std::size_t i = 0; i < c.size(); ++i) {
      s.custom.push_back(custom_candidate(d, c[i], yamlutil::index(join(P, "custom"), i), known));
      known.push_back(s.custom.back().id);
    }
  }
  if (const YAML::Node c = n["candidates"]) {
    d.require_sequence(c, join(P, "candidates"));
    s.learned_correction = false;
    for (std::size_t i = 0; i < c.size(); ++i) {
      const std::string key = yamlutil::index(join(P, "candidates"), i);
      const std::string id = d.choice(c[i], key, known);
      if (id == "unnamed")
        s.learned_correction = true;
      else
        s.candidates.push_back(id);
    }
    if (s.candidates.empty())
      d.fail(c, join(P, "candidates"),
             "names no candidate to screen ('unnamed' is refitted only when the named ones "
             "fail)");
  }
  if (const YAML::Node c = n["exclude"]) {
    d.require_sequence(c, join(P, "exclude"));
    for (std::size_t i = 0; i < c.size(); ++i) {
      const std::string key = yamlutil::index(join(P, "exclude"), i);
      const std::string id = d.choice(c[i], key, known);
      if (id == "unnamed")
        s.learned_correction = false;
      else
        s.exclude.push_back(id);
    }
  }
  if (const YAML::Node r = n["refits"]) {
    s.refits = bounded_integer(d, r, join(P, "refits"), 0, 20);
  }
  if (const YAML::Node r = n["refit_evaluations"]) {
    s.refit_evaluations = bounded_integer(d, r, join(P, "refit_evaluations"), 1, 100000);
  }
  if (const YAML::Node a = n["significance"]) {
    const double v = d.number(a, join(P, "significance"));
    if (!(v > 0 && v < 0.5))
      d.fail(a, join(P, "significance"), fmt::format("must lie in (0, 0.5) (got {:g})", v));
    s.alpha = v;
  }
  if (const YAML::Node f = n["missing_force"]) {
    const std::string FP = join(P, "missing_force");
    MissingForceSettings& m = s.missing_force;
    if (f.IsScalar()) {
      m.enabled = d.choice(f, FP, {"true", "false"}) == "true";
    } else {
      d.require_map(f, FP);
      d.check_keys(f, FP, {"evaluations", "knots_per_second", "segments"});
      if (const YAML::Node v = f["evaluations"]) {
        m.evaluations = bounded_integer(d, v, join(FP, "evaluations"), 1, 100000);
      }
      if (const YAML::Node v = f["knots_per_second"]) {
        const double k = d.number(v, join(FP, "knots_per_second"));
        if (!(k > 0 && k <= 1000))
          d.fail(v, join(FP, "knots_per_second"),
                 fmt::format("must be in (0, 1000] (got {:g})", k));
        m.knots_per_second = k;
      }
      if (const YAML::Node v = f["segments"]) {
        m.segments = bounded_integer(d, v, join(FP, "segments"), 1, 100);
      }
    }
  }
  if (const YAML::Node v = n["validate"]) {
    d.require_sequence(v, join(P, "validate"));
    for (std::size_t i = 0; i < v.size(); ++i)
      s.validate.push_back(
          std::filesystem::absolute(d.existing_file(v[i], yamlutil::index(join(P, "validate"), i)))
              .lexically_normal()
              .string());
  }
  return s;
}

}  // namespace kelvin
