#include "diagnose/learned_correction.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "materials/spline_material.hpp"

namespace kelvin {
namespace {

/// Knots within this distance of the rest state are free: the strains a shaken or
/// sagging soft body reaches; further knots would only add unidentified values.
constexpr double kReach = 0.2 + 1e-9;

double newtonian_viscosity(const Scenario& s) {
  for (const auto& t : s.material.viscous)
    if (t.model == "newtonian" && t.params.count("nu")) return t.params.at("nu");
  return NAN;
}

YAML::Node free_value(const std::string& target, double scale) {
  YAML::Node p(YAML::NodeType::Map);
  p["target"] = target;
  p["log"] = false;
  p["scale"] = scale;
  return p;
}

}  // namespace

Candidate learned_correction(const Scenario& s) {
  Candidate c;
  c.id = "unnamed";
  c.description =
      "a learned stress correction: principal-stretch spline (elastic) and strain-dependent "
      "viscosity (rate), nested at zero";
  const double modulus = largest_modulus(s), nu = newtonian_viscosity(s);
  c.extend = [modulus, nu](const Candidate&, ModelEdits& m, YAML::Node& params, bool) {
    YAML::Node spline(YAML::NodeType::Map);
    spline["model"] = "spline";
    const auto& xs = SplineMaterial::stretch_knots();
    const auto& xj = SplineMaterial::volume_knots();
    for (std::size_t k = 0; k < xs.size(); ++k) spline[fmt::format("f{}", k + 1)] = 0.0;
    for (std::size_t k = 0; k < xj.size(); ++k) spline[fmt::format("h{}", k + 1)] = 0.0;
    m.elastic.push_back(spline);
    const int e = static_cast<int>(m.elastic.size()) - 1;
    // A tenth of the modulus: a 10 % stiffness change moves f′(1.2) by ~0.04 M.
    for (std::size_t k = 0; k < xs.size(); ++k)
      if (xs[k] != 1.0 && std::abs(xs[k] - 1) <= kReach)
        params.push_back(free_value(fmt::format("elastic[{}].f{}", e, k + 1), 0.1 * modulus));
    for (std::size_t k = 0; k < xj.size(); ++k)
      if (xj[k] != 1.0 && std::abs(xj[k] - 1) <= kReach)
        params.push_back(free_value(fmt::format("elastic[{}].h{}", e, k + 1), 0.1 * modulus));

    YAML::Node damping(YAML::NodeType::Map);
    damping["model"] = "strain-damping";
    damping["d0"] = 0.0;
    damping["d1"] = 0.0;
    damping["d2"] = 0.0;
    m.viscous.push_back(damping);
    const int v = static_cast<int>(m.viscous.size()) - 1;
    // ν(σ) − ν(1) ≈ d1 (σ − 1): d1 of 10 ν is a 100 % change at a 10 % stretch.
    const double scale = std::isfinite(nu) && nu > 0 ? 10 * nu : 1.0;
    if (!(std::isfinite(nu) && nu > 0)) {
      YAML::Node d0 = free_value(fmt::format("viscous[{}].d0", v), 1.0);
      d0["lower"] = 0.0;
      params.push_back(d0);
    }
    params.push_back(free_value(fmt::format("viscous[{}].d1", v), scale));
    params.push_back(free_value(fmt::format("viscous[{}].d2", v), 10 * scale));
  };
  return c;
}

CorrectionSignature correction_signature(const Scenario& s, const std::vector<NamedValue>& fitted) {
  CorrectionSignature sig;
  const double modulus = largest_modulus(s), nu = newtonian_viscosity(s);
  const auto& xs = SplineMaterial::stretch_knots();
  const auto& xj = SplineMaterial::volume_knots();
  double d0 = 0, d1 = 0, d2 = 0;
  for (const auto& v : fitted) {
    const std::string name = v.name.substr(v.name.rfind('.') + 1);
    if (name.size() < 2) continue;
    const int number = std::atoi(name.c_str() + 1), k = number - 1;  // f1, h1 at knot 0
    SignaturePoint p;
    p.value = v.value;
    p.std_error = v.std_error;
    if (name[0] == 'f' && k >= 0 && k < static_cast<int>(xs.size())) {
      p.kind = "stretch";
      p.at = xs[k];
    } else if (name[0] == 'h' && k >= 0 && k < static_cast<int>(xj.size())) {
      p.kind = "volume";
      p.at = xj[k];
    } else if (name[0] == 'd') {
      (number == 0 ? d0 : number == 1 ? d1 : d2) = v.value;
      continue;
    } else {
      continue;
    }
    p.relative = p.value / (modulus * std::abs(p.at - 1));
    sig.points.push_back(p);
  }
  for (double at : {1.1, 1.2}) {
    SignaturePoint p;
    p.kind = "damping";
    p.at = at;
    p.value = d0 + d1 * (at - 1) + d2 * (at - 1) * (at - 1);
    p.relative = std::isfinite(nu) && nu > 0 ? p.value / nu : NAN;
    sig.points.push_back(p);
  }

  // A stress correction of the sign of (s − 1) stiffens, the other sign softens.
  std::vector<std::string> words;
  for (const char* kind : {"stretch", "volume"}) {
    for (bool tension : {true, false}) {
      const SignaturePoint* big = nullptr;
      for (const auto& p : sig.points)
        if (p.kind == kind && (p.at > 1) == tension &&
            (!big || std::abs(p.relative) > std::abs(big->relative)))
          big = &p;
      if (!big) continue;
      const double stiffer = tension ? big->relative : -big->relative;
      const char* x = std::string(kind) == "stretch" ? "s" : "J";
      words.push_back(fmt::format("{} {} 1: {} ({:+.0f} % of M·|{} − 1| at {} = {:.2g})", x,
                                  tension ? ">" : "<", stiffer > 0 ? "stiffer" : "softer",
                                  100 * stiffer, x, x, big->at));
    }
  }
  const SignaturePoint& damp = sig.points.back();
  words.push_back(std::isfinite(damp.relative)
                      ? fmt::format("damping {:+.0f} % of ν at a largest stretch of {:.2g}",
                                    100 * damp.relative, damp.at)
                      : fmt::format("extra viscosity {:.3g} Pa s at a largest stretch of {:.2g}",
                                    damp.value, damp.at));
  for (const auto& w : words) sig.summary += (sig.summary.empty() ? "" : "; ") + w;
  return sig;
}

}  // namespace kelvin
