// The `material:` and `mesh:` sections.
#include <fmt/format.h>

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>

#include "base/error.hpp"
#include "engine/csv.hpp"
#include "engine/mesh_refine.hpp"
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
  // Beyond this, products in the tangent and the Newton solve overflow doubles.
  constexpr double kMaxModulus = 1e20;
  if (p.unit == "Pa" && std::abs(v) > kMaxModulus)
    return fmt::format("is beyond any material (at most {:g} Pa; kelvin's units are SI)",
                       kMaxModulus);
  if (v >= p.lower && v <= p.upper) return "";
  if (v < p.lower && p.upper >= 1e300)
    return fmt::format("must be at least {}", with_unit(p.lower, p.unit));
  if (v > p.upper && p.lower <= -1e300)
    return fmt::format("must be at most {}", with_unit(p.upper, p.unit));
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

/// One term (a mapping) or several (a list of mappings) whose stresses add up.
std::vector<MaterialTermSpec> load_terms(const Doc& d, const Node& n, const std::string& P,
                                         bool viscous) {
  if (!n.IsSequence()) return {load_term(d, n, P, viscous)};
  if (n.size() == 0)
    d.fail(n, P, "lists no term; give one mapping { model: ... } or a list of them");
  std::vector<MaterialTermSpec> terms;
  for (size_t k = 0; k < n.size(); ++k)
    terms.push_back(load_term(d, n[k], yamlutil::index(P, k), viscous));
  return terms;
}

/// A `material.fields` file as written, with its format checked (the targets and
/// values are checked against the material by the caller, the element count
/// against the mesh).
struct FieldsTable {
  std::string path;
  int header_line = 0;
  std::vector<std::string> targets;  // the header after `element`
  struct Row {
    int line = 0;
    int element = 0;
    std::vector<double> values;  // one per target
  };
  std::vector<Row> rows;
};

FieldsTable read_fields_table(const std::string& path) {
  FieldsTable t;
  t.path = path;
  std::map<int, int> line_of;  // element → line of its row
  for (const auto& [n, line] : read_csv_lines(path)) {
    auto cells = split_csv_line(line);
    if (t.header_line == 0) {
      if (cells[0] != "element" || cells.size() < 2)
        throw Error(
            fmt::format("{}:{}: the header must be 'element' followed by the fields' "
                        "targets, e.g. element,density,elastic.mu (got '{}')",
                        path, n, line));
      t.header_line = n;
      t.targets.assign(cells.begin() + 1, cells.end());
      continue;
    }
    if (cells.size() != t.targets.size() + 1)
      throw Error(fmt::format("{}:{}: {} columns, the header has {}", path, n, cells.size(),
                              t.targets.size() + 1));
    FieldsTable::Row row;
    row.line = n;
    char* end = nullptr;
    const long id = std::strtol(cells[0].c_str(), &end, 10);
    if (cells[0].empty() || *end != '\0' || id < 0 || id > INT_MAX)
      throw Error(
          fmt::format("{}:{}: column 1 (element) '{}' is not an element id (a whole "
                      "number from 0)",
                      path, n, cells[0]));
    row.element = static_cast<int>(id);
    if (const auto [it, fresh] = line_of.emplace(row.element, n); !fresh)
      throw Error(fmt::format("{}:{}: element {} appears twice (first on line {})", path, n,
                              row.element, it->second));
    for (size_t k = 1; k < cells.size(); ++k) {
      double v = 0;
      if (!parse_csv_number(cells[k], v) || !std::isfinite(v))
        throw Error(fmt::format("{}:{}: column {} ({}) '{}' is not a finite number", path, n, k + 1,
                                t.targets[k - 1], cells[k]));
      row.values.push_back(v);
    }
    t.rows.push_back(std::move(row));
  }
  if (t.header_line == 0)
    throw Error(fmt::format("{}: empty file (expected a header element,<target>,...)", path));
  if (t.rows.empty()) throw Error(fmt::format("{}: no element rows after the header", path));
  return t;
}

/// Every element 0 … n−1 must have a row. Before the mesh is known, n is the row
/// count, which finds gaps; with the mesh, the ids are checked against its size.
void check_elements(const FieldsTable& t, int n, bool mesh) {
  const int rows = static_cast<int>(t.rows.size());
  for (const auto& r : t.rows) {
    if (r.element < n) continue;
    if (mesh)
      throw Error(
          fmt::format("{}:{}: element {} is beyond the mesh, which has {} elements "
                      "(0 … {})",
                      t.path, r.line, r.element, n, n - 1));
    std::vector<bool> seen(n);
    for (const auto& o : t.rows)
      if (o.element < n) seen[o.element] = true;
    const int missing = static_cast<int>(std::find(seen.begin(), seen.end(), false) - seen.begin());
    throw Error(
        fmt::format("{}:{}: element {} is listed, but element {} has no row (every "
                    "element needs exactly one)",
                    t.path, r.line, r.element, missing));
  }
  if (rows < n)
    throw Error(
        fmt::format("{}:{}: the file ends after element {}, but the mesh has {} "
                    "elements: {} … {} have no row",
                    t.path, t.rows.back().line, rows - 1, n, rows, n - 1));
}

std::vector<MaterialField> load_fields(const FieldsTable& t, const MaterialSpec& m) {
  const std::vector<MaterialQuantity> known = material_quantities(m);
  std::vector<std::string> names;
  for (const auto& q : known) names.push_back(q.name);

  const int n = static_cast<int>(t.rows.size());
  check_elements(t, n, false);
  std::vector<MaterialField> fields;
  for (size_t c = 0; c < t.targets.size(); ++c) {
    const std::string& target = t.targets[c];
    const MaterialQuantity* q = find_quantity(known, target);
    if (!q) {
      const std::string hint = yamlutil::suggestion(target, names, "valid");
      throw Error(fmt::format(
          "{}:{}: column {}: '{}' is not a quantity of this material; {}{}", t.path, t.header_line,
          c + 2, target, hint,
          hint.rfind("did you mean", 0) == 0 ? " (valid: " + names_list(names) + ")" : ""));
    }
    for (size_t o = 0; o < c; ++o)
      if (find_quantity(known, t.targets[o]) == q)
        throw Error(fmt::format("{}:{}: column {}: '{}' is given twice (first in column {})",
                                t.path, t.header_line, c + 2, target, o + 2));
    MaterialField f{q->name, q->term, q->index, Eigen::VectorXd(n)};
    for (const auto& r : t.rows) {
      const double v = r.values[c];
      const std::string problem = param_problem(q->info, v);
      if (!problem.empty())
        throw Error(fmt::format("{}:{}: column {} ({}) of element {}: {}{} (got {})", t.path,
                                r.line, c + 2, target, r.element, problem,
                                q->model.empty() ? "" : " for model '" + q->model + "'",
                                with_unit(v, q->info.unit)));
      f.values[r.element] = v;
    }
    fields.push_back(std::move(f));
  }
  return fields;
}

int axis_index(const Doc& d, const Node& n, const std::string& path) {
  return d.choice(n, path, {"x", "y", "z"})[0] - 'x';
}

void check_tet_count(const Doc& d, const Node& n, const std::string& path, double tets,
                     const std::string& what) {
  if (tets > kMaxMeshTets)
    d.fail(n, path,
           fmt::format("{} would make {:.3g} tetrahedra, more than kelvin meshes (at most {:.0e})",
                       what, tets, kMaxMeshTets));
}

Mesh generate(const Doc& d, const Node& m) {
  const std::string kind =
      d.choice(d.required(m, "mesh", "generate"), "mesh.generate", {"box", "cylinder"});
  if (kind == "box") {
    d.check_keys(m, "mesh", {"generate", "lo", "hi", "size", "element_size", "refine"});
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
    check_tet_count(d, m["element_size"], "mesh.element_size", box_tet_count(lo, hi, h),
                    fmt::format("{:g} m", h));
    return generate_box(lo, hi, h);
  }
  d.check_keys(m, "mesh", {"generate", "radius", "height", "element_size", "axis", "refine"});
  const double r = d.positive(d.required(m, "mesh", "radius"), "mesh.radius", "m");
  const double len = d.positive(d.required(m, "mesh", "height"), "mesh.height", "m");
  const double h = d.positive(d.required(m, "mesh", "element_size"), "mesh.element_size", "m");
  const int axis = m["axis"] ? axis_index(d, m["axis"], "mesh.axis") : 2;
  check_tet_count(d, m["element_size"], "mesh.element_size", cylinder_tet_count(r, len, h),
                  fmt::format("{:g} m", h));
  return generate_cylinder(r, len, h, axis);
}

}  // namespace

MaterialSpec load_material(const Doc& d, const Node& n) {
  d.check_keys(n, "material", {"density", "elastic", "viscous", "fields"});
  MaterialSpec m;
  m.density = d.positive(d.required(n, "material", "density"), "material.density", "kg/m³");
  m.elastic = load_terms(d, d.required(n, "material", "elastic"), "material.elastic", false);
  if (n["viscous"]) m.viscous = load_terms(d, n["viscous"], "material.viscous", true);
  if (const Node f = n["fields"]) {
    m.fields_path = d.existing_file(f, "material.fields");
    try {
      m.fields = load_fields(read_fields_table(m.fields_path), m);
    } catch (const Error& e) {
      d.fail(f, "material.fields", e.what());
    }
  }
  return m;
}

namespace {

Mesh read_or_generate(const Doc& d, const Node& m) {
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
  d.check_keys(m, "mesh", {"file", "refine"});
  const Node f = m["file"];
  const std::string file = d.existing_file(f, "mesh.file");
  const std::string ext = std::filesystem::path(file).extension().string();
  if (ext != ".msh" && ext != ".node" && ext != ".ele")
    d.fail(
        f, "mesh.file",
        fmt::format("unknown mesh format '{}'; expected .msh (Gmsh) or .node/.ele (TetGen)", ext));
  Mesh mesh;
  try {
    mesh = read_mesh(file);
    validate_mesh(mesh);
  } catch (const Error& e) {
    d.fail(f, "mesh.file", e.what());
  }
  return mesh;
}

}  // namespace

Mesh load_mesh(const Doc& d, const Node& m) {
  Mesh mesh = read_or_generate(d, m);
  if (const Node r = m["refine"]) {
    // A mesh-convergence check on the same geometry: each level splits every
    // tetrahedron into eight.
    const long levels = d.integer(r, "mesh.refine");
    if (levels < 0 || levels > 3)
      d.fail(r, "mesh.refine",
             fmt::format("{} levels: give 0 … 3 (each one multiplies the "
                         "tetrahedra by 8)",
                         levels));
    check_tet_count(d, r, "mesh.refine",
                    mesh.num_tets() * std::pow(8.0, static_cast<double>(levels)),
                    fmt::format("{} levels", levels));
    mesh = refine_uniformly(mesh, static_cast<int>(levels));
  }
  // The material (and its fields file) is read before the mesh, so whether the
  // fields cover the mesh can only be told here; the file is read again, being
  // small next to the mesh, rather than widening the sections' interface.
  const Node material = d.root()["material"];
  if (material.IsMap() && material["fields"]) {
    const Node f = material["fields"];
    if (m["refine"] && d.integer(m["refine"], "mesh.refine") > 0)
      d.fail(m["refine"], "mesh.refine",
             "material.fields gives values per element of the unrefined mesh; refine the mesh "
             "where the fields were made, or drop the fields");
    try {
      check_elements(read_fields_table(d.existing_file(f, "material.fields")), mesh.num_tets(),
                     true);
    } catch (const Error& e) {
      d.fail(f, "material.fields", e.what());
    }
  }
  return mesh;
}

}  // namespace kelvin::scenario_detail

namespace kelvin {

const MaterialTermSpec& MaterialSpec::term(int t) const {
  const int ne = static_cast<int>(elastic.size());
  return t < ne ? elastic.at(t) : viscous.at(t - ne);
}

MaterialTermSpec& MaterialSpec::term(int t) {
  const int ne = static_cast<int>(elastic.size());
  return t < ne ? elastic.at(t) : viscous.at(t - ne);
}

std::vector<MaterialQuantity> material_quantities(const MaterialSpec& m) {
  std::vector<MaterialQuantity> out;
  MaterialQuantity density;
  density.name = density.indexed = "density";
  density.info.unit = "kg/m³";
  density.info.positive = true;
  density.info.lower = 0;
  density.value = m.density;
  out.push_back(density);
  for (bool is_viscous : {false, true}) {
    const auto& list = is_viscous ? m.viscous : m.elastic;
    const std::string kind = is_viscous ? "viscous" : "elastic";
    std::map<std::string, int> count;  // parameter name → terms of this kind that have it
    std::vector<std::vector<ParamInfo>> params;
    for (const auto& term : list) {
      params.push_back(create_material(term.model, term.plugin)->params());
      for (const auto& p : params.back()) ++count[p.name];
    }
    for (size_t k = 0; k < list.size(); ++k)
      for (size_t i = 0; i < params[k].size(); ++i) {
        const ParamInfo& p = params[k][i];
        MaterialQuantity q;
        q.indexed = fmt::format("{}[{}].{}", kind, k, p.name);
        q.name = count[p.name] == 1 ? kind + "." + p.name : q.indexed;
        q.term = m.term_index(is_viscous, static_cast<int>(k));
        q.index = static_cast<int>(i);
        q.model = list[k].model;
        q.info = p;
        const auto v = list[k].params.find(p.name);
        q.value = v == list[k].params.end() ? p.default_value : v->second;
        out.push_back(q);
      }
  }
  return out;
}

const MaterialQuantity* find_quantity(const std::vector<MaterialQuantity>& quantities,
                                      const std::string& name) {
  for (const auto& q : quantities)
    if (q.name == name || q.indexed == name) return &q;
  return nullptr;
}

}  // namespace kelvin
