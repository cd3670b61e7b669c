// The `fit:` section: which material quantities are fitted (and over which part of
// the body), the misfit, the optimiser and its stopping rules. Everything that can
// be checked against the rest of the scenario (the model's parameter names and
// ranges, marker names, the run's duration, further experiment files) is checked
// here, so that a fit never starts on a file it would refuse hours later.
#include <fmt/format.h>

#include <algorithm>
#include <climits>
#include <cmath>
#include <filesystem>

#include "base/error.hpp"
#include "materials/material.hpp"
#include "yaml/scenario_sections.hpp"

namespace kelvin::scenario_detail {
namespace {

using YAML::Node;
using yamlutil::Doc;
using yamlutil::join;
using Scope = FitParameterSpec::Scope;

/// At most this many knots in time per body-force target.
constexpr int kMaxForceKnots = 2000;

/// What a fit target can be, and its default range and transform.
struct TargetInfo {
  std::string name;  // the quantity's canonical name (MaterialQuantity::name)
  std::string unit;
  double lower = -1e300, upper = 1e300;             // admissible range
  double default_lower = NAN, default_upper = NAN;  // default bounds (NaN: the range)
  bool positive = false;
  double current = 0;   // the scenario's value, the default start
  bool scalar = false;  // one value for the whole model (global scope only)
};

std::vector<std::string> valid_targets(const std::vector<MaterialQuantity>& quantities) {
  std::vector<std::string> names;
  for (const auto& q : quantities) names.push_back(q.name);
  names.push_back(kElasticModuli);
  names.push_back(kClockOffset);
  names.push_back(kRegistration);
  names.push_back("markers.<name>.offset");
  names.push_back("clamps.<name>.compliance");
  for (const char* axis : {"x", "y", "z"}) names.push_back(std::string("body_force.") + axis);
  return names;
}

std::string names_list(const std::vector<std::string>& names) {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

TargetInfo resolve_target(const Doc& d, const Node& at, const std::string& P,
                          const std::string& target, const Scenario& s) {
  if (target == kClockOffset || target == kRegistration ||
      !marker_of_offset_target(target).empty()) {
    const std::string marker = marker_of_offset_target(target);
    if (!marker.empty() && std::none_of(s.markers.embedded.begin(), s.markers.embedded.end(),
                                        [&](const MarkerEmbedding& m) { return m.name == marker; }))
      d.fail(at, P, fmt::format("'{}' names no marker of this scenario (markers.rest)", target));
    TargetInfo t;
    t.name = target;
    // Observations are linear around 0, the capture as recorded.
    t.unit = target == kClockOffset ? "s" : (target == kRegistration ? "rad, m" : "m");
    t.default_lower = target == kClockOffset ? -0.1 : (target == kRegistration ? -0.1 : -0.02);
    t.default_upper = -t.default_lower;
    t.positive = false;
    t.current = 0;
    t.scalar = true;
    return t;
  }
  if (const std::string name = clamp_of_compliance_target(target); !name.empty()) {
    const auto clamp = std::find_if(s.clamps.begin(), s.clamps.end(),
                                    [&](const ClampSpec& c) { return c.name == name; });
    if (clamp == s.clamps.end())
      d.fail(at, P, fmt::format("'{}' names no clamp of this scenario (clamps)", target));
    if (clamp->compliance <= 0)
      d.fail(at, P,
             fmt::format("clamp '{}' is rigid; give it a 'compliance' (or 'stiffness') to fit "
                         "its compliance from",
                         name));
    TargetInfo t;
    t.name = target;
    t.unit = "m³/N";
    t.lower = 1e-300;  // 0 would be the rigid clamp, which has no springs to soften
    t.positive = true;
    t.current = clamp->compliance;
    t.scalar = true;
    return t;
  }
  if (body_force_axis(target) >= 0) {
    TargetInfo t;
    t.name = target;
    t.unit = "m/s²";
    t.default_lower = -1e3;  // a hundred g: far beyond a missing force, finite for the optimiser
    t.default_upper = 1e3;
    t.current = 0;  // the nominal model has none
    return t;
  }
  if (target == kElasticModuli) {
    TargetInfo t;
    t.name = target;
    t.unit = "1";
    t.lower = 0;
    t.positive = true;
    t.current = 1;  // a multiplier of the scenario's moduli
    return t;
  }
  const std::vector<MaterialQuantity> quantities = material_quantities(s.material);
  if (const MaterialQuantity* q = find_quantity(quantities, target)) {
    TargetInfo t;
    t.name = q->name;
    t.unit = q->info.unit;
    t.lower = q->info.lower;
    t.upper = q->info.upper;
    t.positive = q->info.positive;
    t.current = q->value;
    return t;
  }
  const auto names = valid_targets(quantities);
  if (target.rfind("viscous", 0) == 0 && s.material.viscous.empty())
    d.fail(at, P,
           fmt::format("'{}' names a viscous parameter, but the material has no viscous term "
                       "(material.viscous); fittable: {}",
                       target, names_list(names)));
  const std::string hint = yamlutil::suggestion(target, names, "fittable");
  d.fail(at, P,
         fmt::format(
             "'{}' is not a fittable quantity of this scenario; {}{}", target, hint,
             hint.rfind("did you mean", 0) == 0 ? " (fittable: " + names_list(names) + ")" : ""));
}

bool boolean(const Doc& d, const Node& n, const std::string& path) {
  const std::string v = d.string(n, path);
  bool b = false;
  try {
    b = n.as<bool>();
  } catch (const YAML::Exception&) {
    d.fail(n, path, fmt::format("must be true or false (got '{}')", v));
  }
  return b;
}

int int_at_least(const Doc& d, const Node& n, const std::string& path, long min) {
  const long v = d.integer(n, path);
  if (v < min)
    d.fail(n, path,
           min == 0 ? fmt::format("must not be negative (got {})", v)
                    : fmt::format("must be at least {} (got {})", min, v));
  if (v > INT_MAX) d.fail(n, path, fmt::format("is too large (got {}; at most {})", v, INT_MAX));
  return static_cast<int>(v);
}

std::string fmt_bound(double v) {
  if (v >= 1e300) return "+inf";
  if (v <= -1e300) return "-inf";
  return fmt::format("{:g}", v);
}

std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> load_boxes(const Doc& d, const Node& n,
                                                                    const std::string& P) {
  d.check_keys(n, P, {"boxes"});
  const std::string BP = join(P, "boxes");
  const Node list = d.required(n, P, "boxes");
  d.require_sequence(list, BP);
  if (list.size() == 0)
    d.fail(list, BP, "must list at least one box {min: [x, y, z], max: [x, y, z]}");
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> boxes;
  for (size_t k = 0; k < list.size(); ++k) {
    const Node b = list[k];
    const std::string KP = yamlutil::index(BP, k);
    d.check_keys(b, KP, {"min", "max"});
    const Eigen::Vector3d lo = d.vec3(d.required(b, KP, "min"), join(KP, "min"));
    const Node max_node = d.required(b, KP, "max");
    const Eigen::Vector3d hi = d.vec3(max_node, join(KP, "max"));
    for (int i = 0; i < 3; ++i)
      if (hi[i] <= lo[i])
        d.fail(max_node, join(KP, "max"),
               fmt::format("must exceed min in every coordinate (max.{0} = {1:g} is not above "
                           "min.{0} = {2:g})",
                           "xyz"[i], hi[i], lo[i]));
    boxes.emplace_back(lo, hi);
  }
  return boxes;
}

/// `{ legendre: { axis: z, degree: 2, from: 1 } }`.
void load_legendre(const Doc& d, const Node& n, const std::string& P, FitParameterSpec& spec) {
  d.check_keys(n, P, {"legendre"});
  const std::string LP = join(P, "legendre");
  const Node l = n["legendre"];
  d.require_map(l, LP);
  d.check_keys(l, LP, {"axis", "degree", "from"});
  spec.legendre_axis =
      d.choice(d.required(l, LP, "axis"), join(LP, "axis"), {"x", "y", "z"})[0] - 'x';
  spec.legendre_degree = int_at_least(d, d.required(l, LP, "degree"), join(LP, "degree"), 0);
  if (spec.legendre_degree > 10)
    d.fail(l["degree"], join(LP, "degree"),
           fmt::format("must be at most 10 (got {}): a smooth field along the body needs few "
                       "terms, and high degrees oscillate between the elements",
                       spec.legendre_degree));
  if (const Node from = l["from"]) {
    spec.legendre_from = int_at_least(d, from, join(LP, "from"), 0);
    if (spec.legendre_from > spec.legendre_degree)
      d.fail(from, join(LP, "from"),
             fmt::format("must be at most the degree {} (got {})", spec.legendre_degree,
                         spec.legendre_from));
  }
}

/// Default range of a Legendre coefficient: the field may vary by e^±5 (≈ 150×).
constexpr double kLegendreBound = 5;

const char* scope_name(Scope scope) {
  switch (scope) {
    case Scope::Global:
      return "global";
    case Scope::PerRegion:
      return "per-region";
    case Scope::PerElement:
      return "per-element";
    case Scope::Boxes:
      return "boxes";
    case Scope::Legendre:
      return "legendre";
  }
  return "";
}

FitParameterSpec load_parameter(const Doc& d, const Node& n, const std::string& P,
                                const Scenario& s) {
  FitParameterSpec spec;
  spec.line = n.Mark().line + 1;
  // `- elastic.mu` is short for `- { target: elastic.mu }`.
  const bool shorthand = n.IsScalar();
  if (!shorthand)
    d.check_keys(
        n, P, {"target", "initial", "lower", "upper", "log", "scope", "scale", "knots", "penalty"});
  const Node target_node = shorthand ? n : d.required(n, P, "target");
  const std::string TP = shorthand ? P : join(P, "target");
  spec.target = d.string(target_node, TP);
  const TargetInfo info = resolve_target(d, target_node, TP, spec.target, s);
  spec.target = info.name;  // one spelling per quantity: elastic[0].mu is elastic.mu
  const std::string what = fmt::format("'{}'", spec.target);
  auto range = [&](double lo, double hi) {
    return fmt::format("[{}, {}]{}", fmt_bound(lo), fmt_bound(hi),
                       info.unit.empty() || info.unit == "1" ? "" : " " + info.unit);
  };

  spec.lower = std::isnan(info.default_lower) ? info.lower : info.default_lower;
  spec.upper = std::isnan(info.default_upper) ? info.upper : info.default_upper;
  spec.log = info.positive;
  if (shorthand) {
    spec.scope = Scope::Global;
  } else if (const Node sc = n["scope"]; sc && sc.IsMap() && sc["legendre"]) {
    // The coefficients of a multiplier field: 0 is the scenario's field.
    if (body_force_axis(spec.target) >= 0)
      d.fail(sc, join(P, "scope"),
             fmt::format("{} is a value field: its scope is global, per-region, per-element or "
                         "boxes (a Legendre scope multiplies a quantity, and the nominal force "
                         "is 0)",
                         what));
    for (const char* key : {"knots", "penalty"})
      if (n[key])
        d.fail(n[key], join(P, key),
               fmt::format("applies to value parameters, not to a Legendre field's coefficients"));
    spec.scope = Scope::Legendre;
    load_legendre(d, sc, join(P, "scope"), spec);
    if (n["log"])
      d.fail(n["log"], join(P, "log"), "a Legendre field is fitted in log space already");
    if (n["scale"])
      d.fail(n["scale"], join(P, "scale"),
             "a Legendre field's coefficients are exponents already (unit steps)");
    spec.log = false;
    spec.lower = n["lower"] ? d.number(n["lower"], join(P, "lower")) : -kLegendreBound;
    spec.upper = n["upper"] ? d.number(n["upper"], join(P, "upper")) : kLegendreBound;
    if (spec.lower >= spec.upper)
      d.fail(n["upper"] ? n["upper"] : n["lower"], join(P, n["upper"] ? "upper" : "lower"),
             fmt::format("lower ({:g}) must be below upper ({:g})", spec.lower, spec.upper));
    spec.initial = n["initial"] ? d.number(n["initial"], join(P, "initial")) : 0.0;
    if (*spec.initial < spec.lower || *spec.initial > spec.upper)
      d.fail(n["initial"], join(P, "initial"),
             fmt::format("{:g} is outside [lower, upper] = [{:g}, {:g}] (Legendre coefficients)",
                         *spec.initial, spec.lower, spec.upper));
    return spec;
  } else {
    const Node lo = n["lower"], hi = n["upper"];
    if (lo) spec.lower = d.number(lo, join(P, "lower"));
    if (hi) spec.upper = d.number(hi, join(P, "upper"));
    const Node log_node = n["log"];
    if (log_node) spec.log = boolean(d, log_node, join(P, "log"));
    if (const Node sc = n["scale"]) {
      spec.scale = d.number(sc, join(P, "scale"));
      if (!(spec.scale > 0) || !std::isfinite(spec.scale))
        d.fail(sc, join(P, "scale"), fmt::format("must be positive (got {:g})", spec.scale));
      if (spec.log)
        d.fail(sc, join(P, "scale"),
               fmt::format("{} is fitted in log space, where steps are relative already; scale "
                           "applies to log: false",
                           what));
    }
    if (spec.log && spec.lower < 0) {
      if (lo)
        d.fail(lo, join(P, "lower"),
               fmt::format("a log-transformed parameter must stay positive, but lower is {:g}; "
                           "raise lower to 0 or more, or set log: false",
                           spec.lower));
      d.fail(log_node, join(P, "log"),
             fmt::format("{} may be negative (its range is {}); a log-transformed parameter "
                         "needs lower: 0 or more",
                         what, range(info.lower, info.upper)));
    }

    // Bounds beyond the model's admissible range would let the optimiser try values
    // the model refuses.
    if (lo && (spec.lower < info.lower || spec.lower > info.upper))
      d.fail(lo, join(P, "lower"),
             fmt::format("{:g} is outside the admissible range {} of {}", spec.lower,
                         range(info.lower, info.upper), what));
    if (hi && (spec.upper < info.lower || spec.upper > info.upper))
      d.fail(hi, join(P, "upper"),
             fmt::format("{:g} is outside the admissible range {} of {}", spec.upper,
                         range(info.lower, info.upper), what));
    if (spec.lower >= spec.upper)
      d.fail(hi ? hi : lo, join(P, hi ? "upper" : "lower"),
             fmt::format("lower ({}) must be below upper ({})", fmt_bound(spec.lower),
                         fmt_bound(spec.upper)));

    if (const Node v = n["initial"]) {
      const double x = d.number(v, join(P, "initial"));
      if (x < spec.lower || x > spec.upper)
        d.fail(
            v, join(P, "initial"),
            fmt::format("{:g} is outside [lower, upper] = {}", x, range(spec.lower, spec.upper)));
      if (spec.log && x <= 0)
        d.fail(v, join(P, "initial"),
               fmt::format("a log-transformed parameter must start positive (got {:g})", x));
      spec.initial = x;
    }

    if (const Node sc = n["scope"]) {
      const std::string SP = join(P, "scope");
      if (sc.IsMap()) {
        spec.scope = Scope::Boxes;
        spec.boxes = load_boxes(d, sc, SP);
      } else {
        const std::string v = d.choice(sc, SP, {"global", "per-region", "per-element"});
        spec.scope = v == "global"       ? Scope::Global
                     : v == "per-region" ? Scope::PerRegion
                                         : Scope::PerElement;
      }
    }
  }

  const bool force = body_force_axis(spec.target) >= 0;
  if (const Node k = shorthand ? Node(YAML::NodeType::Undefined) : n["knots"]) {
    if (!force)
      d.fail(k, join(P, "knots"),
             fmt::format("knots are the time basis of a body force (body_force.x|y|z), not of {}",
                         what));
    const double v = d.number(k, join(P, "knots"));
    if (v != std::floor(v) || v < 1 || v > kMaxForceKnots)
      d.fail(k, join(P, "knots"),
             fmt::format("must be a whole number from 1 to {} (got {:g})", kMaxForceKnots, v));
    spec.knots = static_cast<int>(v);
  } else if (force) {
    d.fail(n, P,
           fmt::format("{} needs 'knots': how many hats in time over [0, time.end] = [0, {:g}] s "
                       "(resolving f Hz takes about 4 f per second)",
                       what, s.time.end));
  }
  if (const Node w = shorthand ? Node(YAML::NodeType::Undefined) : n["penalty"]) {
    spec.penalty = d.non_negative(w, join(P, "penalty"), "m² s");
    if (spec.log)
      d.fail(w, join(P, "penalty"),
             fmt::format("a penalty is a Gaussian prior at 0, and {} is fitted in log space; set "
                         "log: false",
                         what));
  }
  if (info.scalar && spec.scope != Scope::Global)
    d.fail(n["scope"], join(P, "scope"),
           fmt::format("{} is one value for the whole model: its scope is global", what));
  // Without `initial` the fit starts from the scenario's own value.
  if (!spec.initial) {
    if (info.current < spec.lower || info.current > spec.upper)
      d.fail(n, P,
             fmt::format("{} starts at the scenario's value {:g}, outside [lower, upper] = {}; "
                         "give 'initial' or widen the bounds",
                         what, info.current, range(spec.lower, spec.upper)));
    if (spec.log && info.current <= 0)
      d.fail(n, P,
             fmt::format("{} starts at the scenario's value {:g}, but a log-transformed "
                         "parameter must start positive; give 'initial' or set log: false",
                         what, info.current));
  }
  return spec;
}

/// `fit.objective.targets`: shapes the body should reach at given times.
std::vector<ShapeTargetSpec> load_targets(const Doc& d, const Node& n, const std::string& P,
                                          const Scenario& s) {
  d.require_sequence(n, P);
  if (n.size() == 0) d.fail(n, P, "the list is empty (leave the key out for no target)");
  std::vector<ShapeTargetSpec> targets;
  for (size_t k = 0; k < n.size(); ++k) {
    const Node e = n[k];
    const std::string EP = yamlutil::index(P, k);
    d.require_map(e, EP);
    d.check_keys(e, EP, {"name", "time", "select", "offset", "plane", "positions", "weight"});
    ShapeTargetSpec t;
    t.line = e.Mark().line + 1;
    t.name = e["name"] ? d.string(e["name"], join(EP, "name")) : fmt::format("target{}", k + 1);
    for (const auto& other : targets)
      if (other.name == t.name)
        d.fail(e["name"] ? e["name"] : e, join(EP, "name"),
               fmt::format("'{}' is already the name of another target", t.name));
    const Node time = d.required(e, EP, "time");
    t.time = d.non_negative(time, join(EP, "time"), "s");
    if (t.time > s.time.end)
      d.fail(time, join(EP, "time"),
             fmt::format("{:g} s is after the end of the run (time.end = {:g} s)", t.time,
                         s.time.end));
    const Node offset = e["offset"], plane = e["plane"], positions = e["positions"];
    if (positions) {
      // The file names the nodes and where each should be.
      for (const char* key : {"select", "offset", "plane"})
        if (e[key])
          d.fail(e[key], join(EP, key),
                 "a target given by 'positions' (node,x,y,z rows) names its nodes and their "
                 "places itself; leave out 'select', 'offset' and 'plane'");
      t.positions_path = d.existing_file(positions, join(EP, "positions"));
      try {
        NodePositions rows = read_node_positions(t.positions_path, s.mesh.num_nodes());
        t.nodes = std::move(rows.nodes);
        t.positions = std::move(rows.positions);
      } catch (const Error& err) {
        d.fail(positions, join(EP, "positions"), err.what());
      }
    } else {
      select_entry_nodes(d, e, EP, s.mesh, t.selection, t.nodes);
    }
    if (offset && plane)
      d.fail(plane, join(EP, "plane"),
             "give 'offset' (every axis: the rest positions moved) or 'plane' (one axis: a flat "
             "face), not both");
    if (offset) {
      t.offset = d.vec3(offset, join(EP, "offset"));
    } else if (plane) {
      const std::string PP = join(EP, "plane");
      d.require_map(plane, PP);
      d.check_keys(plane, PP, {"axis", "at"});
      t.plane_axis =
          d.choice(d.required(plane, PP, "axis"), join(PP, "axis"), {"x", "y", "z"})[0] - 'x';
      t.plane_at = d.number(d.required(plane, PP, "at"), join(PP, "at"));
    } else if (!positions) {
      d.fail(e, EP,
             "says no target shape: give 'offset: [dx, dy, dz]' (m, from the rest positions), "
             "'plane: {axis, at}' (the selected nodes on that plane) or 'positions: file.csv' "
             "(node,x,y,z rows)");
    }
    if (const Node w = e["weight"]) t.weight = d.positive(w, join(EP, "weight"), "s");
    targets.push_back(std::move(t));
  }
  return targets;
}

void load_objective(const Doc& d, const Node& n, const Scenario& s, ObjectiveSpec& obj) {
  const std::string P = "fit.objective";
  d.check_keys(n, P, {"weights", "window", "targets"});
  if (const Node t = n["targets"]) obj.targets = load_targets(d, t, join(P, "targets"), s);
  if (const Node w = n["weights"]) {
    const std::string WP = join(P, "weights");
    d.require_map(w, WP);
    std::vector<std::string> names;
    for (const auto& m : s.markers.embedded) names.push_back(m.name);
    for (auto it = w.begin(); it != w.end(); ++it) {
      const std::string key = d.string(it->first, WP);
      const std::string KP = join(WP, key);
      if (names.empty())
        d.fail(it->first.Mark(), KP, "the scenario has no markers (markers.rest) to weight");
      if (std::find(names.begin(), names.end(), key) == names.end())
        d.fail(it->first.Mark(), KP,
               fmt::format("'{}' is not a marker of this scenario; {}", key,
                           yamlutil::suggestion(key, names, "markers")));
      if (obj.weights.count(key)) d.fail(it->first.Mark(), KP, "is given twice");
      obj.weights[key] = d.non_negative(it->second, KP, "");
    }
  }
  if (const Node win = n["window"]) {
    const std::string WP = join(P, "window");
    if (!win.IsSequence() || win.size() != 2)
      d.fail(win, WP, "must be a list of two times [begin, end] in s");
    const double a = d.non_negative(win[0], yamlutil::index(WP, 0), "s");
    const double b = d.number(win[1], yamlutil::index(WP, 1));
    if (b <= a)
      d.fail(win[1], yamlutil::index(WP, 1),
             fmt::format("the window must end after it begins (got [{:g}, {:g}] s)", a, b));
    if (b > s.time.end)
      d.fail(win[1], yamlutil::index(WP, 1),
             fmt::format("{:g} s is after the end of the run (time.end = {:g} s)", b, s.time.end));
    obj.window_begin = a;
    obj.window_end = b;
  }
}

}  // namespace

FitSpec load_fit(const Doc& d, const Node& n, const Scenario& s) {
  const std::string P = "fit";
  d.check_keys(n, P,
               {"parameters", "objective", "gradient", "algorithm", "max_evaluations", "ftol_rel",
                "xtol_rel", "max_seconds", "smoothness", "spline_slope_penalty", "lcurve",
                "experiments", "checkpoint_steps", "segment", "start_rtol", "start_scan"});
  FitSpec f;
  f.present = true;

  const std::string PP = join(P, "parameters");
  const Node params = d.required(n, P, "parameters");
  d.require_sequence(params, PP);
  if (params.size() == 0)
    d.fail(params, PP,
           fmt::format("must list at least one parameter to fit (fittable: {})",
                       names_list(valid_targets(material_quantities(s.material)))));
  for (size_t i = 0; i < params.size(); ++i) {
    const std::string IP = yamlutil::index(PP, i);
    FitParameterSpec spec = load_parameter(d, params[i], IP, s);
    for (const auto& prev : f.parameters)
      if (prev.target == spec.target && prev.scope == spec.scope)
        d.fail(params[i], IP,
               fmt::format("'{}' with scope {} is already fitted by the entry on line {}",
                           spec.target, scope_name(spec.scope), prev.line));
    // The model holds one body-force field, so one time basis.
    for (const auto& prev : f.parameters)
      if (spec.knots && prev.knots && spec.knots != prev.knots)
        d.fail(params[i]["knots"], join(IP, "knots"),
               fmt::format("{} knots, but the body force on line {} has {}: one field, one time "
                           "basis",
                           spec.knots, prev.line, prev.knots));
    f.parameters.push_back(std::move(spec));
  }

  if (const Node o = n["objective"]) load_objective(d, o, s, f.objective);

  const Node grad = n["gradient"], alg = n["algorithm"];
  if (grad) f.gradient = d.choice(grad, join(P, "gradient"), {"adjoint", "forward", "none"});
  if (alg) f.algorithm = d.choice(alg, join(P, "algorithm"), {"lbfgs", "mma", "slsqp", "bobyqa"});
  if (f.algorithm == "bobyqa") {
    if (!grad)
      f.gradient = "none";  // derivative-free: computing gradients would be wasted work
    else if (f.gradient != "none")
      d.fail(grad, join(P, "gradient"),
             fmt::format("algorithm bobyqa is derivative-free and uses no gradient; set "
                         "gradient: none or pick lbfgs, mma or slsqp (got '{}')",
                         f.gradient));
  } else if (f.gradient == "none") {
    d.fail(grad, join(P, "gradient"),
           fmt::format("algorithm {} needs gradients; use gradient: adjoint or forward, or the "
                       "derivative-free algorithm: bobyqa",
                       f.algorithm));
  }

  if (const Node v = n["max_evaluations"])
    f.max_evaluations = int_at_least(d, v, join(P, "max_evaluations"), 1);
  if (const Node v = n["ftol_rel"]) f.ftol_rel = d.non_negative(v, join(P, "ftol_rel"), "");
  if (const Node v = n["xtol_rel"]) f.xtol_rel = d.non_negative(v, join(P, "xtol_rel"), "");
  if (const Node v = n["max_seconds"])
    f.max_seconds = d.non_negative(v, join(P, "max_seconds"), "s");
  if (const Node v = n["start_rtol"]) {
    f.start_rtol = d.positive(v, join(P, "start_rtol"), "");
    if (f.start_rtol < s.solver.rtol || f.start_rtol >= 1)
      d.fail(v, join(P, "start_rtol"),
             fmt::format("must lie in [solver.rtol, 1) = [{:g}, 1): the fit's stages only tighten "
                         "the tolerances, down to solver.rtol (got {:g})",
                         s.solver.rtol, f.start_rtol));
  }
  if (const Node v = n["start_scan"])
    f.start_scan = d.choice(v, join(P, "start_scan"), {"stiffness", "none"});
  if (const Node v = n["smoothness"]) f.smoothness = d.non_negative(v, join(P, "smoothness"), "");
  if (const Node v = n["spline_slope_penalty"])
    f.spline_slope_penalty = d.non_negative(v, join(P, "spline_slope_penalty"), "m² s/Pa²");
  if (const Node v = n["lcurve"]) {
    const std::string LP = join(P, "lcurve");
    d.require_sequence(v, LP);
    for (size_t i = 0; i < v.size(); ++i)
      f.lcurve.push_back(d.positive(v[i], yamlutil::index(LP, i), ""));
  }
  if (const Node v = n["experiments"]) {
    const std::string EP = join(P, "experiments");
    d.require_sequence(v, EP);
    for (size_t i = 0; i < v.size(); ++i) {
      // Absolute, so that it means the same file whatever directory it is joined to.
      const std::string file = d.existing_file(v[i], yamlutil::index(EP, i));
      f.experiments.push_back(std::filesystem::absolute(file).lexically_normal().string());
    }
  }
  if (const Node v = n["checkpoint_steps"])
    f.checkpoint_steps = int_at_least(d, v, join(P, "checkpoint_steps"), 0);
  if (const Node v = n["segment"]) f.segment = d.non_negative(v, join(P, "segment"), "s");
  return f;
}

}  // namespace kelvin::scenario_detail

namespace kelvin {

double fit_start_tolerance_scale(const Scenario& s) {
  const double rtol = s.solver.rtol;
  const double start = s.fit.start_rtol > 0 ? s.fit.start_rtol : std::min(1e-3, 100 * rtol);
  return std::max(1.0, start / rtol);
}

}  // namespace kelvin
