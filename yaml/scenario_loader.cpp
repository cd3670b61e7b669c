// Scenario files: YAML → a fully resolved Scenario. Every refusal points at the
// offending text (file:line:col) and names the key path, because the person who
// reads the message is editing that file. The cheap sections (time, solver,
// material) are checked before the mesh is built, so that a typo costs nothing.
#include <fmt/format.h>

#include <cmath>
#include <filesystem>

#include "base/error.hpp"
#include "yaml/scenario.hpp"
#include "yaml/scenario_sections.hpp"
#include "yaml/yaml_util.hpp"

namespace kelvin {
namespace {

using YAML::Node;
using yamlutil::Doc;

TimeSpec load_time(const Doc& d, const Node& n) {
  const std::string P = "time";
  d.check_keys(n, P, {"end", "output_rate", "vtu_rate"});
  TimeSpec t;
  t.end = d.positive(d.required(n, P, "end"), "time.end", "s");
  if (n["output_rate"]) t.output_rate = d.positive(n["output_rate"], "time.output_rate", "Hz");
  if (n["vtu_rate"]) t.vtu_rate = d.non_negative(n["vtu_rate"], "time.vtu_rate", "Hz");
  if (const std::string why = time_span_problem(t); !why.empty()) d.fail(n, P, why);
  return t;
}

SolverSpec load_solver(const Doc& d, const Node& n) {
  const std::string P = "solver";
  d.check_keys(n, P,
               {"rtol", "atol", "velocity_atol_scale", "max_order", "max_steps", "max_step",
                "initial_step", "mass"});
  SolverSpec s;
  if (n["rtol"]) {
    s.rtol = d.positive(n["rtol"], "solver.rtol", "");
    if (s.rtol >= 1)
      d.fail(
          n["rtol"], "solver.rtol",
          fmt::format("is a relative tolerance and must be below 1 (got {:g}; the default is 1e-4)",
                      s.rtol));
  }
  if (n["atol"]) s.atol = d.positive(n["atol"], "solver.atol", "m");
  if (n["velocity_atol_scale"])
    s.velocity_atol_scale = d.positive(n["velocity_atol_scale"], "solver.velocity_atol_scale", "");
  if (n["max_order"] && !(n["max_order"].IsScalar() && n["max_order"].Scalar() == "auto")) {
    const long q = d.integer(n["max_order"], "solver.max_order");
    if (q < 1 || q > 5)
      d.fail(n["max_order"], "solver.max_order",
             fmt::format("must be 'auto' or between 1 and 5, the orders IDAS offers (got {})", q));
    s.max_order = static_cast<int>(q);
  }
  if (n["max_steps"]) {
    s.max_steps = d.integer(n["max_steps"], "solver.max_steps");
    if (s.max_steps <= 0)
      d.fail(n["max_steps"], "solver.max_steps",
             fmt::format("must be positive (got {})", s.max_steps));
  }
  if (n["max_step"]) s.max_step = d.non_negative(n["max_step"], "solver.max_step", "s");
  if (n["initial_step"])
    s.initial_step = d.non_negative(n["initial_step"], "solver.initial_step", "s");
  if (s.max_step > 0 && s.initial_step > s.max_step)
    d.fail(n["initial_step"], "solver.initial_step",
           fmt::format("({:g} s) exceeds solver.max_step ({:g} s)", s.initial_step, s.max_step));
  if (n["mass"])
    s.lumped_mass = d.choice(n["mass"], "solver.mass", {"lumped", "consistent"}) == "lumped";
  return s;
}

}  // namespace

std::string time_span_problem(const TimeSpec& t) {
  if (!(t.end > 0) || !std::isfinite(t.end))
    return fmt::format("the end time must be positive and finite (got {})", t.end);
  if (!(t.end * t.output_rate <= kMaxOutputFrames))
    return fmt::format(
        "{:g} s at an output rate of {:g} Hz are {:.3g} marker frames, more than "
        "the {:g} a run can hold; lower time.output_rate or time.end",
        t.end, t.output_rate, t.end * t.output_rate, kMaxOutputFrames);
  if (!(t.end * t.vtu_rate <= kMaxVtuFrames))
    return fmt::format(
        "{:g} s at a VTU rate of {:g} Hz are {:.3g} VTU frames, more than the {:g} "
        "a run can write; lower time.vtu_rate",
        t.end, t.vtu_rate, t.end * t.vtu_rate, kMaxVtuFrames);
  return "";
}

Scenario load_scenario(const std::string& path) {
  const Doc d(path);
  const Node& root = d.root();
  d.check_keys(root, "",
               {"name", "mesh", "material", "gravity", "initial", "clamps", "loads", "markers",
                "time", "solver", "fit", "diagnose", "probing"});
  Scenario s;
  s.path = path;
  s.name =
      root["name"] ? d.string(root["name"], "name") : std::filesystem::path(path).stem().string();
  if (s.name.empty()) d.fail(root["name"], "name", "must not be empty");

  // A scenario of static measurements alone (`probing:`) runs no time.
  if (root["time"] || !root["probing"]) s.time = load_time(d, d.required(root, "", "time"));
  if (root["solver"]) s.solver = load_solver(d, root["solver"]);
  if (root["gravity"]) s.gravity = d.vec3(root["gravity"], "gravity");
  if (root["initial"])
    s.static_initial = d.choice(root["initial"], "initial", {"static", "rest"}) == "static";
  s.material = scenario_detail::load_material(d, d.required(root, "", "material"));

  s.mesh = scenario_detail::load_mesh(d, d.required(root, "", "mesh"));
  if (s.mesh.reordered > 0)
    s.notes.push_back(fmt::format(
        "{}: {} of the {} tetrahedra were listed in negative orientation (as dolfin and some "
        "other tools write them) and were reordered",
        s.mesh.source, s.mesh.reordered, s.mesh.num_tets()));
  if (root["clamps"] && !root["clamps"].IsNull())
    s.clamps = scenario_detail::load_clamps(d, root["clamps"], s.mesh, s.time);
  if (root["loads"] && !root["loads"].IsNull())
    s.loads = scenario_detail::load_loads(d, root["loads"], s.mesh, s.clamps);
  if (s.static_initial && s.clamps.empty())
    d.fail(root["initial"], "initial",
           "static needs at least one clamp: an unclamped body under load has no equilibrium");
  if (root["markers"]) s.markers = scenario_detail::load_markers(d, root["markers"], s.mesh);
  // `fit` is checked last: it refers to the material, the markers and the run time.
  if (root["fit"]) {
    s.fit = scenario_detail::load_fit(d, root["fit"], s);
    s.fit.present = true;
  }
  // `diagnose` and `probing` belong to their drivers, which read them from the file
  // itself; here they are only reserved names.
  return s;
}

}  // namespace kelvin
