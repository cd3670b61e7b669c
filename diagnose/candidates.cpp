#include "diagnose/candidates.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "engine/clamp_spring.hpp"

namespace kelvin {
namespace {

YAML::Node term(const std::string& model, const std::vector<std::pair<std::string, double>>& p) {
  YAML::Node t(YAML::NodeType::Map);
  t["model"] = model;
  for (const auto& [name, value] : p) t[name] = value;
  return t;
}

YAML::Node parameter(const std::string& target, std::optional<double> lower = std::nullopt) {
  YAML::Node p(YAML::NodeType::Map);
  p["target"] = target;
  if (lower) p["lower"] = *lower;
  return p;
}

/// A smooth field along the body without its mean (the global parameters carry it).
YAML::Node legendre_field(const std::string& target, int axis) {
  YAML::Node p = parameter(target);
  YAML::Node l(YAML::NodeType::Map);
  l["axis"] = std::string(1, "xyz"[axis]);
  l["degree"] = 3;
  l["from"] = 1;
  p["scope"]["legendre"] = l;
  return p;
}

/// Appends `t` to `list` and returns its index there.
int append(YAML::Node& list, const YAML::Node& t) {
  list.push_back(t);
  return static_cast<int>(list.size()) - 1;
}

YAML::Node fibre(const Eigen::Vector3d& a) {
  const Eigen::Vector3d d = a.normalized();
  return term("fibre", {{"k", 0.0},
                        {"theta", std::acos(std::clamp(d.z(), -1.0, 1.0))},
                        {"phi", std::atan2(d.y(), d.x())}});
}

/// The pads of a clamp_compliance candidate (engine/clamp_spring.hpp).
struct ClampPads {
  double scale = 0;  // m³/N: a tenth of the body's own compliance L/M
  /// m³/N: the nominal, 10⁻⁴ of that (the clamp face sinks tens of nanometres). At
  /// 10⁻⁵ the error-controlled Φ quadrature took 100× the steps (a 0.1 s run of the
  /// shaken test bar: > 100 s against 1.1 s; the states alone 1 s either way).
  double rigid = 0;
  double damping_time = 0;  // s
};

/// The body's compliance L/M (L its length, M its largest modulus) sets the scale;
/// the pads' retardation time is 1/20 rad at the capture's Nyquist frequency: it keeps
/// the stiff nominal pad overdamped (τ² ≫ 4 c m/A) while its phase lag on the
/// captured motion stays below 0.05 rad.
ClampPads nested_pads(const Scenario& s) {
  const Eigen::Vector3d extent =
      s.mesh.nodes.rowwise().maxCoeff() - s.mesh.nodes.rowwise().minCoeff();
  ClampPads p;
  p.scale = 0.1 * extent.maxCoeff() / largest_modulus(s);
  p.rigid = 1e-4 * p.scale;
  const auto& times = s.markers.observed.times;
  const double rate =
      times.size() > 1 ? (times.size() - 1) / (times.back() - times.front()) : s.time.output_rate;
  p.damping_time = 0.05 / (2 * M_PI * 0.5 * rate);
  return p;
}

}  // namespace

double largest_modulus(const Scenario& s) {
  double modulus = 0;
  for (const auto& q : material_quantities(s.material))
    if (q.info.unit == "Pa") modulus = std::max(modulus, std::abs(q.value));
  return modulus > 0 ? modulus : 1.0;
}

BodyAxis body_axis(const Scenario& s) {
  BodyAxis b;
  const Eigen::Vector3d lo = s.mesh.nodes.rowwise().minCoeff(),
                        hi = s.mesh.nodes.rowwise().maxCoeff();
  (hi - lo).maxCoeff(&b.axis);
  Eigen::Vector3d clamped = Eigen::Vector3d::Zero();
  int count = 0;
  for (const auto& c : s.clamps)
    for (int n : c.nodes) {
      clamped += s.mesh.nodes.col(n);
      ++count;
    }
  const double mid = 0.5 * (lo[b.axis] + hi[b.axis]);
  const bool high = count > 0 && clamped[b.axis] / count > mid;
  b.clamp_end = high ? hi[b.axis] : lo[b.axis];
  b.free_end = high ? lo[b.axis] : hi[b.axis];
  return b;
}

std::vector<Eigen::Vector3d> screening_directions() {
  std::vector<Eigen::Vector3d> d = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                    Eigen::Vector3d::UnitZ()};
  for (int i = 0; i < 3; ++i)
    for (double s : {1.0, -1.0}) {
      Eigen::Vector3d a = Eigen::Vector3d::Zero();
      a[i] = 1;
      a[(i + 1) % 3] = s;
      d.push_back(a.normalized());
    }
  for (double sy : {1.0, -1.0})
    for (double sz : {1.0, -1.0}) d.push_back(Eigen::Vector3d(1, sy, sz).normalized());
  return d;
}

const std::vector<std::string>& candidate_ids() {
  static const std::vector<std::string> ids = {
      "stiffening",       "damping_law",    "drag",     "inhomogeneity", "added_mass",
      "anisotropy",       "relaxation",     "sync_lag", "marker_offset", "registration",
      "clamp_compliance", "discretisation", "unnamed"};
  return ids;
}

std::vector<double> screening_relaxation_times(const Scenario& s) {
  const double frame = s.time.output_rate > 0 ? 1.0 / s.time.output_rate : s.time.end / 100;
  std::vector<double> times;
  for (double tau = 2 * frame; tau <= 0.5 * s.time.end; tau *= 3) times.push_back(tau);
  if (times.empty()) times.push_back(0.5 * s.time.end);
  return times;
}

Candidate custom_candidate(const CustomCandidateSpec& spec) {
  Candidate c;
  c.id = spec.id;
  c.where = spec.where;
  c.description = spec.description.empty() ? "the user's candidate " + spec.id : spec.description;
  c.origin = spec.place;
  c.extend = [spec](const Candidate&, ModelEdits& m, YAML::Node& params, bool) {
    int k = -1;
    if (!spec.kind.empty())
      k = append(spec.kind == "elastic" ? m.elastic : m.viscous, YAML::Clone(spec.term));
    for (const auto& entry : spec.parameters) {
      YAML::Node e = YAML::Clone(entry);
      const std::string target = e["target"].Scalar();
      if (target.rfind("term.", 0) == 0)
        e["target"] = fmt::format("{}[{}].{}", spec.kind, k, target.substr(5));
      params.push_back(e);
    }
  };
  return c;
}

std::vector<Candidate> builtin_candidates(const Scenario& s) {
  std::vector<Candidate> out;
  const int axis = body_axis(s).axis;

  Candidate stiffening;
  stiffening.id = "stiffening";
  stiffening.description = "a Yeoh-like stiffening term c₂ (I₁ − 3 − 2 ln J)²";
  stiffening.extend = [](const Candidate&, ModelEdits& m, YAML::Node& params, bool) {
    const int k = append(m.elastic, term("stiffening", {{"c2", 0.0}}));
    params.push_back(parameter(fmt::format("elastic[{}].c2", k), 0.0));
  };
  out.push_back(stiffening);

  const auto& viscous = s.material.viscous;
  const auto newtonian =
      std::find_if(viscous.begin(), viscous.end(),
                   [](const MaterialTermSpec& t) { return t.model == "newtonian"; });
  if (newtonian != viscous.end()) {
    Candidate law;
    law.id = "damping_law";
    law.description = "a power-law viscosity (flow index h, 1 = the Newtonian nominal)";
    const int k = static_cast<int>(newtonian - viscous.begin());
    const double nu = newtonian->params.at("nu");
    law.extend = [k, nu](const Candidate&, ModelEdits& m, YAML::Node& params, bool) {
      m.viscous[k] = term("power-law", {{"nu", nu}, {"h", 1.0}});
      params.push_back(parameter(fmt::format("viscous[{}].h", k)));
    };
    out.push_back(law);
  }

  Candidate drag;
  drag.id = "drag";
  drag.description = "a mass-proportional drag force −c ρ v (air drag, Rayleigh α₀)";
  drag.extend = [](const Candidate&, ModelEdits& m, YAML::Node& params, bool) {
    const int k = append(m.viscous, term("drag", {{"c", 0.0}}));
    params.push_back(parameter(fmt::format("viscous[{}].c", k), 0.0));
  };
  out.push_back(drag);

  Candidate inhomogeneity;
  inhomogeneity.id = "inhomogeneity";
  inhomogeneity.description = "a stiffness that varies along the body (Legendre P₁–P₃ field)";
  inhomogeneity.extend = [axis](const Candidate&, ModelEdits&, YAML::Node& params, bool) {
    params.push_back(legendre_field(kElasticModuli, axis));
  };
  out.push_back(inhomogeneity);

  Candidate mass;
  mass.id = "added_mass";
  mass.description = "a density that varies along the body (Legendre P₁–P₃ field)";
  mass.extend = [axis](const Candidate&, ModelEdits&, YAML::Node& params, bool) {
    params.push_back(legendre_field("density", axis));
  };
  out.push_back(mass);

  Candidate anisotropy;
  anisotropy.id = "anisotropy";
  anisotropy.description = "a fibre term k/2 (‖F a‖² − 1)² along a direction a";
  anisotropy.alternatives = true;
  anisotropy.extend = [](const Candidate& self, ModelEdits& m, YAML::Node& params, bool screening) {
    const auto directions = screening_directions();
    if (screening) {
      for (const auto& a : directions) {
        const int k = append(m.elastic, fibre(a));
        params.push_back(parameter(fmt::format("elastic[{}].k", k), 0.0));
      }
      return;
    }
    const int k = append(
        m.elastic, fibre(self.choice >= 0 ? directions[self.choice] : Eigen::Vector3d::UnitZ()));
    params.push_back(parameter(fmt::format("elastic[{}].k", k), 0.0));
    params.push_back(parameter(fmt::format("elastic[{}].theta", k)));
    params.push_back(parameter(fmt::format("elastic[{}].phi", k)));
  };
  out.push_back(anisotropy);

  Candidate relaxation;
  relaxation.id = "relaxation";
  relaxation.description =
      "a relaxing branch (Maxwell element: modulus g, relaxation time τ; standard linear solid)";
  relaxation.alternatives = true;
  const std::vector<double> times = screening_relaxation_times(s);
  relaxation.extend = [times](const Candidate& self, ModelEdits& m, YAML::Node& params,
                              bool screening) {
    const auto branch = [&](double tau) {
      const int k = append(m.elastic, term("maxwell", {{"g", 0.0}, {"tau", tau}}));
      params.push_back(parameter(fmt::format("elastic[{}].g", k), 0.0));
      return k;
    };
    if (screening) {
      for (double tau : times) branch(tau);
      return;
    }
    const int k = branch(times[self.choice >= 0 ? self.choice : times.size() / 2]);
    YAML::Node tau = parameter(fmt::format("elastic[{}].tau", k));
    tau["log"] = true;
    params.push_back(tau);
  };
  out.push_back(relaxation);

  for (int k = 0; k < static_cast<int>(s.clamps.size()); ++k) {
    const ClampSpec& clamp = s.clamps[k];
    if (clamp.compliance > 0 || clamp_faces(s.mesh, clamp.nodes, k).empty()) continue;
    Candidate soft;
    soft.id = "clamp_compliance";
    soft.where = s.clamps.size() > 1 ? clamp.name : "";
    soft.description = fmt::format("clamp '{}' holds the body through compliant pads", clamp.name);
    const ClampPads pads = nested_pads(s);
    const std::string target = fmt::format("clamps.{}.compliance", clamp.name);
    soft.extend = [k, pads, target](const Candidate&, ModelEdits& m, YAML::Node& params, bool) {
      m.clamps[k]["compliance"] = pads.rigid;
      m.clamps[k]["damping_time"] = pads.damping_time;
      YAML::Node p = parameter(target, pads.rigid);
      p["log"] = false;
      p["scale"] = pads.scale;
      p["upper"] = 10 * pads.scale;
      params.push_back(p);
    };
    out.push_back(soft);
  }

  if (!s.markers.observed.names.empty()) {
    Candidate lag;
    lag.id = "sync_lag";
    lag.where = "marker clock";
    lag.description = "an offset between the marker clock and the clamp log";
    lag.extend = [](const Candidate&, ModelEdits&, YAML::Node& params, bool) {
      params.push_back(parameter(kClockOffset));
    };
    out.push_back(lag);
  }
  for (const auto& m : s.markers.embedded) {
    const auto& names = s.markers.observed.names;
    if (std::find(names.begin(), names.end(), m.name) == names.end()) continue;
    Candidate offset;
    offset.id = "marker_offset";
    offset.where = m.name;
    offset.description = fmt::format("marker {} sits away from its given rest position", m.name);
    const std::string target = fmt::format("markers.{}.offset", m.name);
    offset.extend = [target](const Candidate&, ModelEdits&, YAML::Node& params, bool) {
      params.push_back(parameter(target));
    };
    out.push_back(offset);
  }
  if (!s.markers.observed.names.empty()) {
    Candidate reg;
    reg.id = "registration";
    reg.where = "capture frame";
    reg.description = "a rigid misregistration of the capture frame against the model's";
    reg.extend = [](const Candidate&, ModelEdits&, YAML::Node& params, bool) {
      params.push_back(parameter(kRegistration));
    };
    out.push_back(reg);
  }

  // The numerical cause, so that it is not reported as a physical one: the mesh
  // refined once (Real2Sim's coarsening study: a coarse mesh is too stiff, and biases
  // what is fitted). Not where per-element values tie the parameters to the mesh.
  const bool per_element =
      !s.material.fields_path.empty() ||
      std::any_of(s.fit.parameters.begin(), s.fit.parameters.end(),
                  [](const auto& p) { return p.scope == FitParameterSpec::Scope::PerElement; });
  if (!per_element && s.mesh.refined < 3 && 8.0 * s.mesh.num_tets() <= kMaxMeshTets) {
    Candidate mesh;
    mesh.id = "discretisation";
    mesh.where = "mesh";
    mesh.screened = false;
    mesh.description =
        fmt::format("the discretisation: each tetrahedron split into eight ({} → {})",
                    s.mesh.num_tets(), 8 * s.mesh.num_tets());
    mesh.extend = [](const Candidate&, ModelEdits& m, YAML::Node&, bool) {
      YAML::Node section = m.root["mesh"];
      section["refine"] = (section["refine"] ? section["refine"].as<int>() : 0) + 1;
    };
    out.push_back(mesh);
  }
  return out;
}

}  // namespace kelvin
