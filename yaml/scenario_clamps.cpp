// The `clamps:`, `loads:` and `markers:` sections: all resolve against the mesh, so
// their messages describe the mesh when a selection or a marker misses it.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <set>

#include "base/error.hpp"
#include "engine/clamp_spring.hpp"
#include "engine/csv.hpp"
#include "yaml/scenario_sections.hpp"

namespace kelvin::scenario_detail {
namespace {

using YAML::Node;
using yamlutil::Doc;
using yamlutil::index;
using yamlutil::join;

std::string vec_str(const Eigen::Vector3d& v) {
  return fmt::format("[{:g}, {:g}, {:g}]", v[0], v[1], v[2]);
}

NodeSelection load_selection(const Doc& d, const Node& n, const std::string& P, const Mesh& mesh) {
  d.check_keys(n, P, {"plane", "box", "nodes"});
  if (n.size() != 1) d.fail(n, P, "give exactly one of 'plane', 'box' or 'nodes'");
  NodeSelection sel;
  if (const Node p = n["plane"]) {
    const std::string PP = join(P, "plane");
    d.check_keys(p, PP, {"axis", "at", "tolerance"});
    sel.kind = NodeSelection::Kind::Plane;
    sel.axis = d.choice(d.required(p, PP, "axis"), join(PP, "axis"), {"x", "y", "z"})[0] - 'x';
    sel.at = d.number(d.required(p, PP, "at"), join(PP, "at"));
    if (p["tolerance"]) sel.tolerance = d.positive(p["tolerance"], join(PP, "tolerance"), "m");
  } else if (const Node b = n["box"]) {
    const std::string BP = join(P, "box");
    d.check_keys(b, BP, {"lo", "hi"});
    sel.kind = NodeSelection::Kind::Box;
    sel.lo = d.vec3(d.required(b, BP, "lo"), join(BP, "lo"));
    sel.hi = d.vec3(d.required(b, BP, "hi"), join(BP, "hi"));
    for (int i = 0; i < 3; ++i)
      if (sel.hi[i] < sel.lo[i])
        d.fail(
            b["hi"], join(BP, "hi"),
            fmt::format("must not be below lo ({} < {} along {})", sel.hi[i], sel.lo[i], "xyz"[i]));
  } else {
    const Node ids = n["nodes"];
    const std::string IP = join(P, "nodes");
    d.require_sequence(ids, IP);
    if (ids.size() == 0) d.fail(ids, IP, "the list is empty");
    sel.kind = NodeSelection::Kind::Ids;
    for (size_t i = 0; i < ids.size(); ++i) {
      const long id = d.integer(ids[i], index(IP, i));
      if (id < 0 || id >= mesh.num_nodes())
        d.fail(ids[i], index(IP, i),
               fmt::format("node {} does not exist (the mesh has {} nodes, numbered from 0)", id,
                           mesh.num_nodes()));
      sel.ids.push_back(static_cast<int>(id));
    }
  }
  return sel;
}

/// Why a selection came out empty, in terms of where the mesh actually is.
std::string explain_empty(const NodeSelection& sel, const Mesh& mesh) {
  const Eigen::Vector3d lo = mesh.nodes.rowwise().minCoeff(), hi = mesh.nodes.rowwise().maxCoeff();
  if (sel.kind == NodeSelection::Kind::Box)
    return fmt::format("selects no node (box {} to {} contains none; the mesh spans {} to {})",
                       vec_str(sel.lo), vec_str(sel.hi), vec_str(lo), vec_str(hi));
  const int a = sel.axis;
  const char ax = "xyz"[a];
  const double tol = sel.tolerance >= 0 ? sel.tolerance : 1e-6 * (hi - lo).norm();
  if (sel.at < lo[a] - tol || sel.at > hi[a] + tol)
    return fmt::format(
        "selects no node (plane {0} = {1:g} lies outside the mesh, which spans {0} in [{2:g}, "
        "{3:g}])",
        ax, sel.at, lo[a], hi[a]);
  double nearest = mesh.nodes(a, 0);
  for (int i = 1; i < mesh.num_nodes(); ++i)
    if (std::abs(mesh.nodes(a, i) - sel.at) < std::abs(nearest - sel.at))
      nearest = mesh.nodes(a, i);
  return fmt::format(
      "selects no node (none lies within {2:g} m of plane {0} = {1:g}; the nearest is at {0} = "
      "{3:g}: move 'at' or give a larger 'tolerance')",
      ax, sel.at, tol, nearest);
}

Sinusoid load_sinusoid(const Doc& d, const Node& n, const std::string& P, bool translation) {
  if (translation)
    d.check_keys(n, P, {"amplitude", "frequency", "phase", "direction"});
  else
    d.check_keys(n, P, {"amplitude", "frequency", "phase"});
  Sinusoid s;
  s.amplitude = d.number(d.required(n, P, "amplitude"), join(P, "amplitude"));
  s.frequency = d.non_negative(d.required(n, P, "frequency"), join(P, "frequency"), "Hz");
  if (n["phase"]) s.phase = d.number(n["phase"], join(P, "phase"));
  if (translation) {
    const Node dn = d.required(n, P, "direction");
    const Eigen::Vector3d dir = d.vec3(dn, join(P, "direction"));
    if (dir.norm() == 0) d.fail(dn, join(P, "direction"), "must not be the zero vector");
    s.direction = dir.normalized();
  }
  return s;
}

std::shared_ptr<RigidMotion> load_sinusoids(const Doc& d, const Node& n, const std::string& P,
                                            const Mesh& mesh, const std::vector<int>& nodes) {
  d.check_keys(n, P, {"translation", "rotation", "axis", "center"});
  std::vector<Sinusoid> tr, rot;
  for (const char* key : {"translation", "rotation"}) {
    const Node list = n[key];
    if (!list) continue;
    const std::string LP = join(P, key);
    d.require_sequence(list, LP);
    for (size_t i = 0; i < list.size(); ++i)
      (key[0] == 't' ? tr : rot).push_back(load_sinusoid(d, list[i], index(LP, i), key[0] == 't'));
  }
  if (tr.empty() && rot.empty()) d.fail(n, P, "give at least one 'translation' or 'rotation' term");
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  if (const Node a = n["axis"]) {
    axis = d.vec3(a, join(P, "axis"));
    if (axis.norm() == 0) d.fail(a, join(P, "axis"), "must not be the zero vector");
    axis.normalize();
  } else if (!rot.empty()) {
    d.fail(n, join(P, "axis"), "missing: rotation terms need the rotation 'axis' [x, y, z]");
  }
  // Rotating a clamp about its own centroid is what a scenario almost always means.
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  if (n["center"]) {
    center = d.vec3(n["center"], join(P, "center"));
  } else {
    for (int i : nodes) center += mesh.nodes.col(i);
    center /= static_cast<double>(nodes.size());
  }
  return std::make_shared<SinusoidMotion>(std::move(tr), std::move(rot), axis, center);
}

std::shared_ptr<RigidMotion> load_motion_file(const Doc& d, const Node& f, const std::string& P,
                                              const TimeSpec& time) {
  const std::string file = d.existing_file(f, P);
  std::shared_ptr<SampledMotion> motion;
  try {
    ClampSamples c = read_clamp_csv(file);
    motion = std::make_shared<SampledMotion>(std::move(c.t), std::move(c.translation),
                                             std::move(c.quaternion_wxyz));
  } catch (const Error& e) {
    d.fail(f, P, e.what());
  }
  const double eps = 1e-9 * std::max(1.0, time.end);
  if (motion->start_time() > eps)
    d.fail(f, P,
           fmt::format("the file starts at t = {:g} s; it must cover the start of the run, t = 0",
                       motion->start_time()));
  if (motion->end_time() < time.end - eps)
    d.fail(f, P,
           fmt::format("the file ends at t = {:g} s, before time.end = {:g} s", motion->end_time(),
                       time.end));
  return motion;
}

/// A `clamps:` or `loads:` entry's name (`<kind><k>` when absent), refused when an
/// earlier entry of the same list has it.
template <class Spec>
std::string unique_name(const Doc& d, const Node& entry, const std::string& P,
                        const std::string& kind, size_t k, const std::vector<Spec>& earlier) {
  const std::string name =
      entry["name"] ? d.string(entry["name"], join(P, "name")) : fmt::format("{}{}", kind, k);
  for (const auto& other : earlier)
    if (other.name == name)
      d.fail(entry["name"], join(P, "name"),
             fmt::format("'{}' is already the name of another {}", name, kind));
  return name;
}

}  // namespace

void select_entry_nodes(const Doc& d, const Node& entry, const std::string& P, const Mesh& mesh,
                        NodeSelection& selection, std::vector<int>& nodes) {
  const Node sel = d.required(entry, P, "select");
  selection = load_selection(d, sel, join(P, "select"), mesh);
  nodes = select_nodes(mesh, selection);
  if (nodes.empty()) d.fail(sel, join(P, "select"), explain_empty(selection, mesh));
}

namespace {

/// A compliant clamp's springs: `compliance` (m³/N) or `stiffness` (N/m³, per area of
/// the held faces), and an optional `damping_time` (s).
void load_compliance(const Doc& d, const Node& c, const std::string& P, ClampSpec& spec) {
  if (c["compliance"] && c["stiffness"])
    d.fail(c["stiffness"], join(P, "stiffness"),
           "give 'compliance' or 'stiffness' (its inverse), not both");
  for (const char* key : {"compliance", "stiffness"})
    if (const Node k = c[key]) {
      const double v = d.number(k, join(P, key));
      if (!(v > 0) || !std::isfinite(v) || 1 / v == 0)
        d.fail(k, join(P, key),
               fmt::format("must be positive and finite (got {:g}); a rigid clamp has neither "
                           "key",
                           v));
      spec.compliance = std::string(key) == "compliance" ? v : 1 / v;
    }
  if (const Node k = c["damping_time"]) {
    if (spec.compliance == 0)
      d.fail(k, join(P, "damping_time"),
             "a dashpot acts beside the clamp's springs: give 'compliance' or 'stiffness' too");
    spec.damping_time = d.number(k, join(P, "damping_time"));
    if (!(spec.damping_time >= 0) || !std::isfinite(spec.damping_time))
      d.fail(k, join(P, "damping_time"),
             fmt::format("must be zero or positive and finite (got {:g})", spec.damping_time));
  }
}

}  // namespace

std::vector<ClampSpec> load_clamps(const Doc& d, const Node& n, const Mesh& mesh,
                                   const TimeSpec& time) {
  d.require_sequence(n, "clamps");
  std::vector<ClampSpec> clamps;
  std::map<int, std::string> owner;  // node → clamp, to refuse conflicting motions
  for (size_t k = 0; k < n.size(); ++k) {
    const Node c = n[k];
    const std::string P = index("clamps", k);
    d.check_keys(c, P, {"name", "select", "motion", "compliance", "stiffness", "damping_time"});
    ClampSpec spec;
    spec.name = unique_name(d, c, P, "clamp", k, clamps);
    select_entry_nodes(d, c, P, mesh, spec.selection, spec.nodes);
    int shared = 0;
    std::string other;
    for (int i : spec.nodes) {
      auto [it, fresh] = owner.emplace(i, spec.name);
      if (!fresh) ++shared, other = it->second;
    }
    if (shared > 0)
      d.fail(c["select"], join(P, "select"),
             fmt::format("shares {} node(s) with clamp '{}'; a node can follow only one motion",
                         shared, other));

    spec.motion = std::make_shared<FixedMotion>();
    if (const Node m = c["motion"]) {
      const std::string MP = join(P, "motion");
      d.check_keys(m, MP, {"sinusoids", "file"});
      if (m.size() != 1) d.fail(m, MP, "give exactly one of 'sinusoids' or 'file'");
      if (m["sinusoids"])
        spec.motion = load_sinusoids(d, m["sinusoids"], join(MP, "sinusoids"), mesh, spec.nodes);
      else
        spec.motion = load_motion_file(d, m["file"], join(MP, "file"), time);
    }
    load_compliance(d, c, P, spec);
    if (spec.compliance > 0 && clamp_faces(mesh, spec.nodes, 0).empty())
      d.fail(c["select"], join(P, "select"),
             "a compliant clamp's springs act on the boundary faces its nodes cover, and "
             "these nodes cover none");
    clamps.push_back(std::move(spec));
  }
  return clamps;
}

std::vector<LoadSpec> load_loads(const Doc& d, const Node& n, const Mesh& mesh,
                                 const std::vector<ClampSpec>& clamps) {
  d.require_sequence(n, "loads");
  std::set<int> clamped;
  for (const auto& c : clamps) clamped.insert(c.nodes.begin(), c.nodes.end());
  std::vector<LoadSpec> loads;
  for (size_t k = 0; k < n.size(); ++k) {
    const Node l = n[k];
    const std::string P = index("loads", k);
    d.check_keys(l, P, {"name", "select", "force", "mass"});
    LoadSpec spec;
    spec.name = unique_name(d, l, P, "load", k, loads);
    if (!l["force"] && !l["mass"])
      d.fail(l, P, "give a force (N, total), a mass (kg, total) or both");
    if (const Node f = l["force"]) spec.force = d.vec3(f, join(P, "force"));
    if (const Node m = l["mass"]) spec.mass = d.non_negative(m, join(P, "mass"), "kg");
    select_entry_nodes(d, l, P, mesh, spec.selection, spec.nodes);
    const bool any_free = std::any_of(spec.nodes.begin(), spec.nodes.end(),
                                      [&](int i) { return clamped.count(i) == 0; });
    if (!any_free)
      d.fail(l["select"], join(P, "select"),
             fmt::format("selects {} node(s), all held by clamps: a clamped node carries no load",
                         spec.nodes.size()));
    loads.push_back(std::move(spec));
  }
  return loads;
}

std::vector<PressSpec> load_presses(const Doc& d, const Node& n, const std::string& P0,
                                    const Mesh& mesh, const std::vector<ClampSpec>& clamps) {
  d.require_sequence(n, P0);
  std::map<int, std::string> owner;  // node → clamp or press holding it
  for (const auto& c : clamps)
    for (int i : c.nodes) owner.emplace(i, "clamp '" + c.name + "'");
  std::vector<PressSpec> presses;
  std::vector<ClampSpec> earlier;
  for (size_t k = 0; k < n.size(); ++k) {
    const Node e = n[k];
    const std::string P = index(P0, k);
    d.check_keys(e, P, {"name", "select", "displacement", "reaction"});
    PressSpec press;
    ClampSpec& spec = press.clamp;
    spec.name = unique_name(d, e, P, "press", k, earlier);
    select_entry_nodes(d, e, P, mesh, spec.selection, spec.nodes);
    for (int i : spec.nodes)
      if (auto [it, fresh] = owner.emplace(i, "press '" + spec.name + "'"); !fresh)
        d.fail(e["select"], join(P, "select"),
               fmt::format("node {} is held by {} already; a node can follow only one motion", i,
                           it->second));
    press.displacement = d.vec3(d.required(e, P, "displacement"), join(P, "displacement"));
    if (const Node r = e["reaction"]) press.reaction = d.vec3(r, join(P, "reaction"));
    spec.motion = std::make_shared<TranslatedMotion>(press.displacement);
    spec.ramped = true;
    earlier.push_back(spec);
    presses.push_back(std::move(press));
  }
  return presses;
}

MarkersSpec load_markers(const Doc& d, const Node& n, const Mesh& mesh) {
  const std::string P = "markers";
  d.check_keys(n, P, {"rest", "observed", "tolerance"});
  MarkersSpec spec;
  const double tol = n["tolerance"] ? d.positive(n["tolerance"], join(P, "tolerance"), "m") : 0.002;
  const Node rest = d.required(n, P, "rest");
  const std::string RP = join(P, "rest");
  std::vector<std::string> names;
  if (rest.IsSequence()) {
    // Inline markers are embedded one by one so that a miss points at its own entry.
    for (size_t i = 0; i < rest.size(); ++i) {
      const Node m = rest[i];
      const std::string MP = index(RP, i);
      d.check_keys(m, MP, {"name", "at"});
      const std::string name = d.string(d.required(m, MP, "name"), join(MP, "name"));
      if (std::find(names.begin(), names.end(), name) != names.end())
        d.fail(m["name"], join(MP, "name"), fmt::format("marker '{}' is given twice", name));
      const Node at = d.required(m, MP, "at");
      const Eigen::Vector3d x = d.vec3(at, join(MP, "at"));
      try {
        auto e = embed_markers(mesh, {name}, x, tol);
        spec.embedded.push_back(e.at(0));
      } catch (const Error& e) {
        d.fail(at, join(MP, "at"), e.what());
      }
      names.push_back(name);
    }
    if (names.empty()) d.fail(rest, RP, "the list is empty");
  } else {
    const std::string file = d.existing_file(rest, RP);
    try {
      MarkerRest r = read_marker_rest(file);
      std::set<std::string> seen;
      for (const auto& name : r.names)
        if (!seen.insert(name).second)
          d.fail(rest, RP, fmt::format("marker '{}' appears twice in {}", name, file));
      spec.embedded = embed_markers(mesh, r.names, r.positions, tol);
      names = r.names;
    } catch (const Error& e) {
      const std::string what = e.what();
      if (what.rfind(d.file() + ":", 0) == 0) throw;
      d.fail(rest, RP, what);
    }
  }
  if (const Node obs = n["observed"]) {
    const std::string OP = join(P, "observed");
    spec.observed_path = d.existing_file(obs, OP);
    MarkerTracks& tracks = spec.observed;
    try {
      tracks = read_marker_tracks(spec.observed_path);
    } catch (const Error& e) {
      d.fail(obs, OP, e.what());
    }
    for (const auto& name : tracks.names)
      if (std::find(names.begin(), names.end(), name) == names.end())
        d.fail(obs, OP,
               fmt::format("marker '{}' is tracked but has no rest position in markers.rest; {}",
                           name, yamlutil::suggestion(name, names, "rest markers")));
  }
  return spec;
}

}  // namespace kelvin::scenario_detail
