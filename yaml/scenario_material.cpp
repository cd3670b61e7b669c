// The `material:` and `mesh:` sections.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "engine/error.hpp"
#include "materials/material.hpp"
#include "yaml/scenario_sections.hpp"

namespace kelvin::scenario_detail {
namespace {

using YAML::Node;
using yamlutil::Doc;
using yamlutil::join;

std::string with_unit(double v, const std::string& unit) {
  return unit.empty() || unit == "1" ? fmt::format("{:g}", v) : fmt::format("{:g} {}", v, unit);
}

std::string names_list(const std::vector<std::string>& names) {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

/// What is wrong with value v of parameter p for the model, or "" when nothing.
std::string param_problem(const ParamInfo& p, double v) {
  if (p.positive && v <= 0) return "must be positive";
  if (v >= p.lower && v <= p.upper) return "";
  if (p.upper >= 1e300) return fmt::format("must be at least {}", with_unit(p.lower, p.unit));
  if (p.lower <= -1e300) return fmt::format("must be at most {}", with_unit(p.upper, p.unit));
  return fmt::format("must be within [{:g}, {:g}]{}", p.lower, p.upper,
                     p.unit.empty() || p.unit == "1" ? "" : " " + p.unit);
}

MaterialTermSpec load_term(const Doc& d, const Node& n, const std::string& P, bool viscous) {
  d.require_map(n, P);
  MaterialTermSpec spec;
  const Node model_node = d.required(n, P, "model");
  spec.model = d.string(model_node, join(P, "model"));
  if (n["plugin"]) spec.plugin = d.resolve(d.string(n["plugin"], join(P, "plugin")));

  std::unique_ptr<Material> model;
  try {
    model = create_material(spec.model, spec.plugin);
  } catch (const Error& e) {
    const auto names = builtin_material_names();
    std::string why = e.what();
    if (spec.plugin.empty()) {
      const std::string hint = yamlutil::suggestion(spec.model, names, "");
      if (hint.rfind("did you mean", 0) == 0) why += "; " + hint;
    }
    d.fail(model_node, join(P, "model"),
           fmt::format("{} (built-in models: {})", why, names_list(names)));
  }
  if (model->is_viscous() != viscous)
    d.fail(model_node, join(P, "model"),
           viscous
               ? fmt::format("'{}' is an elastic model; put it under material.elastic", spec.model)
               : fmt::format("'{}' is a viscous (rate-dependent) model; put it under "
                             "material.viscous",
                             spec.model));

  const auto& params = model->params();
  auto has = [&](const std::string& name) {
    return std::any_of(params.begin(), params.end(),
                       [&](const ParamInfo& p) { return p.name == name; });
  };
  // Engineers think in Young's modulus and Poisson ratio; the Lamé form is what
  // the models take, so E and ν are converted here.
  const bool lame = has("lambda") && has("mu") && !has("E") && !has("nu");
  std::vector<std::string> allowed = {"model", "plugin"};
  if (model->state_size() > 0) allowed.push_back("state");
  for (const auto& p : params) allowed.push_back(p.name);
  if (lame) allowed.insert(allowed.end(), {"E", "nu"});
  d.check_keys(n, P, allowed);

  for (const auto& p : params) {
    const Node v = n[p.name];
    if (!v) {
      spec.params[p.name] = p.default_value;
      continue;
    }
    const double x = d.number(v, join(P, p.name));
    const std::string problem = param_problem(p, x);
    if (!problem.empty())
      d.fail(v, join(P, p.name),
             fmt::format("{} for model '{}' (got {})", problem, spec.model, with_unit(x, p.unit)));
    spec.params[p.name] = x;
  }

  if (lame && (n["E"] || n["nu"])) {
    if (n["lambda"] || n["mu"]) {
      const std::string key = n["lambda"] ? "lambda" : "mu";
      d.fail(d.key_mark(n, key), join(P, key), "give either lambda and mu or E and nu, not both");
    }
    const Node E_node = d.required(n, P, "E"), nu_node = d.required(n, P, "nu");
    const double E = d.positive(E_node, join(P, "E"), "Pa");
    const double nu = d.number(nu_node, join(P, "nu"));
    if (nu >= 0.5)
      d.fail(nu_node, join(P, "nu"),
             fmt::format("Poisson ratio must be below 0.5 (got {:g}): at 0.5 the material is "
                         "incompressible and lambda = E nu / ((1 + nu)(1 - 2 nu)) is infinite",
                         nu));
    if (nu <= -1)
      d.fail(nu_node, join(P, "nu"),
             fmt::format("Poisson ratio must be above -1 (got {:g}): the bulk modulus would not "
                         "be positive",
                         nu));
    const double lambda = E * nu / ((1 + nu) * (1 - 2 * nu)), mu = E / (2 * (1 + nu));
    // A refused λ or μ is reported at the key the user wrote, with the formula.
    for (const auto& p : params) {
      const bool is_lambda = p.name == "lambda";
      if (!is_lambda && p.name != "mu") continue;
      const double v = is_lambda ? lambda : mu;
      const std::string problem = param_problem(p, v);
      if (!problem.empty())
        d.fail(is_lambda ? nu_node : E_node, join(P, is_lambda ? "nu" : "E"),
               fmt::format("E = {:g} Pa and nu = {:g} give {} = {:g} Pa, but model '{}' says {} {}",
                           E, nu, p.name, v, spec.model, p.name, problem));
    }
    spec.params["lambda"] = lambda;
    spec.params["mu"] = mu;
  } else if (lame) {
    const double lambda = spec.params["lambda"], mu = spec.params["mu"];
    const Node at = n["mu"] ? n["mu"] : (n["lambda"] ? n["lambda"] : n);
    if (mu <= 0)
      d.fail(at, join(P, "mu"), fmt::format("shear modulus must be positive (got {:g} Pa)", mu));
    const double nu = lambda / (2 * (lambda + mu));
    if (lambda + mu <= 0 || nu >= 0.5)
      d.fail(n["lambda"] ? n["lambda"] : at, join(P, "lambda"),
             fmt::format("Poisson ratio nu = lambda / (2 (lambda + mu)) = {:g} must be below 0.5 "
                         "(lambda = {:g} Pa, mu = {:g} Pa)",
                         nu, lambda, mu));
    if (3 * lambda + 2 * mu <= 0)
      d.fail(n["lambda"] ? n["lambda"] : at, join(P, "lambda"),
             fmt::format("bulk modulus lambda + 2 mu / 3 must be positive (Poisson ratio {:g} is "
                         "not above -1)",
                         nu));
  }

  if (n["state"]) {
    const Node st = n["state"];
    const std::string SP = join(P, "state");
    d.require_sequence(st, SP);
    if (static_cast<int>(st.size()) != model->state_size())
      d.fail(st, SP,
             fmt::format("model '{}' takes {} state values (got {})", spec.model,
                         model->state_size(), st.size()));
    for (size_t i = 0; i < st.size(); ++i)
      spec.state.push_back(d.number(st[i], yamlutil::index(SP, i)));
  }
  return spec;
}

int axis_index(const Doc& d, const Node& n, const std::string& path) {
  return d.choice(n, path, {"x", "y", "z"})[0] - 'x';
}

Mesh generate(const Doc& d, const Node& m) {
  const std::string kind =
      d.choice(d.required(m, "mesh", "generate"), "mesh.generate", {"box", "cylinder"});
  const double kMaxCells = 2e6;  // beyond this the run would not fit a workstation
  if (kind == "box") {
    d.check_keys(m, "mesh", {"generate", "lo", "hi", "size", "element_size"});
    const double h = d.positive(d.required(m, "mesh", "element_size"), "mesh.element_size", "m");
    Eigen::Vector3d lo = m["lo"] ? d.vec3(m["lo"], "mesh.lo") : Eigen::Vector3d::Zero();
    Eigen::Vector3d hi;
    Node hi_node;
    if (m["size"]) {
      if (m["hi"]) d.fail(d.key_mark(m, "hi"), "mesh.hi", "give either 'hi' or 'size', not both");
      hi_node = m["size"];
      const Eigen::Vector3d size = d.vec3(hi_node, "mesh.size");
      for (int i = 0; i < 3; ++i)
        if (size[i] <= 0)
          d.fail(hi_node, "mesh.size",
                 fmt::format("must be positive in every direction (got {:g} m along {})", size[i],
                             "xyz"[i]));
      hi = lo + size;
    } else {
      if (!m["hi"])
        d.fail(m, "mesh.hi", "missing: a box needs 'hi' (opposite corner to 'lo') or 'size'");
      hi_node = m["hi"];
      hi = d.vec3(hi_node, "mesh.hi");
      for (int i = 0; i < 3; ++i)
        if (hi[i] <= lo[i])
          d.fail(hi_node, "mesh.hi",
                 fmt::format("must exceed lo in every coordinate (hi.{0} = {1:g} is not above "
                             "lo.{0} = {2:g})",
                             "xyz"[i], hi[i], lo[i]));
    }
    const Eigen::Vector3d cells = ((hi - lo) / h).array().ceil();
    if (cells.prod() > kMaxCells)
      d.fail(m["element_size"], "mesh.element_size",
             fmt::format("{:g} m would make about {:.3g} cells ({:g} × {:g} × {:g}); use a larger "
                         "element size",
                         h, cells.prod(), cells[0], cells[1], cells[2]));
    return generate_box(lo, hi, h);
  }
  d.check_keys(m, "mesh", {"generate", "radius", "height", "element_size", "axis"});
  const double r = d.positive(d.required(m, "mesh", "radius"), "mesh.radius", "m");
  const double len = d.positive(d.required(m, "mesh", "height"), "mesh.height", "m");
  const double h = d.positive(d.required(m, "mesh", "element_size"), "mesh.element_size", "m");
  const int axis = m["axis"] ? axis_index(d, m["axis"], "mesh.axis") : 2;
  const double cells = std::pow(std::ceil(2 * r / h), 2) * std::ceil(len / h);
  if (cells > kMaxCells)
    d.fail(
        m["element_size"], "mesh.element_size",
        fmt::format("{:g} m would make about {:.3g} cells; use a larger element size", h, cells));
  return generate_cylinder(r, len, h, axis);
}

}  // namespace

MaterialSpec load_material(const Doc& d, const Node& n) {
  d.check_keys(n, "material", {"density", "elastic", "viscous"});
  MaterialSpec m;
  m.density = d.positive(d.required(n, "material", "density"), "material.density", "kg/m³");
  m.elastic = load_term(d, d.required(n, "material", "elastic"), "material.elastic", false);
  if (n["viscous"]) m.viscous = load_term(d, n["viscous"], "material.viscous", true);
  return m;
}

Mesh load_mesh(const Doc& d, const Node& m) {
  d.require_map(m, "mesh");
  const bool has_file = m["file"].IsDefined(), has_gen = m["generate"].IsDefined();
  if (has_file && has_gen)
    d.fail(d.key_mark(m, "file"), "mesh.file", "give either 'generate' or 'file', not both");
  if (!has_file && !has_gen)
    d.fail(m, "mesh",
           "needs either 'generate: box|cylinder' (a built-in mesh) or 'file: path' (.msh, .node "
           "or .ele)");
  if (has_gen) {
    Mesh mesh;
    try {
      mesh = generate(d, m);
      validate_mesh(mesh);
    } catch (const Error& e) {
      // Our own positioned messages pass through; generator failures get a position.
      const std::string what = e.what();
      if (what.rfind(d.file() + ":", 0) == 0) throw;
      d.fail(m, "mesh", what);
    }
    return mesh;
  }
  d.check_keys(m, "mesh", {"file"});
  const Node f = m["file"];
  const std::string file = d.existing_file(f, "mesh.file");
  const std::string ext = std::filesystem::path(file).extension().string();
  if (ext != ".msh" && ext != ".node" && ext != ".ele")
    d.fail(
        f, "mesh.file",
        fmt::format("unknown mesh format '{}'; expected .msh (Gmsh) or .node/.ele (TetGen)", ext));
  try {
    Mesh mesh = read_mesh(file);
    validate_mesh(mesh);
    return mesh;
  } catch (const Error& e) {
    d.fail(f, "mesh.file", e.what());
  }
}

}  // namespace kelvin::scenario_detail
