#include <algorithm>
#include <functional>
#include <map>

#include "base/error.hpp"
#include "materials/corotational.hpp"
#include "materials/drag.hpp"
#include "materials/fiber.hpp"
#include "materials/fibre_term.hpp"
#include "materials/material.hpp"
#include "materials/maxwell.hpp"
#include "materials/mooney_rivlin.hpp"
#include "materials/neo_hookean.hpp"
#include "materials/plugin_loader.hpp"
#include "materials/power_law.hpp"
#include "materials/rayleigh.hpp"
#include "materials/spline_material.hpp"
#include "materials/stable_neo_hookean.hpp"
#include "materials/stiffening.hpp"
#include "materials/strain_damping.hpp"
#include "materials/stvk.hpp"

namespace kelvin {
namespace {

using Factory = std::function<std::unique_ptr<Material>()>;

const std::map<std::string, Factory>& factories() {
  static const std::map<std::string, Factory> f = {
      {"neo-hookean", [] { return std::make_unique<NeoHookean>(); }},
      {"newtonian", [] { return std::make_unique<NewtonianViscosity>(); }},
      {"power-law", [] { return std::make_unique<PowerLawViscosity>(); }},
      {"rayleigh", [] { return std::make_unique<RayleighDamping>(); }},
      {"stable-neo-hookean", [] { return std::make_unique<StableNeoHookean>(); }},
      {"corotational", [] { return std::make_unique<Corotational>(); }},
      {"stvk", [] { return std::make_unique<StVenantKirchhoff>(); }},
      {"mooney-rivlin", [] { return std::make_unique<MooneyRivlin>(); }},
      {"spline", [] { return std::make_unique<SplineMaterial>(); }},
      {"fiber", [] { return std::make_unique<FiberReinforced>(); }},
      {"strain-damping", [] { return std::make_unique<StrainDamping>(); }},
      {"stiffening", [] { return std::make_unique<Stiffening>(); }},
      {"fibre", [] { return std::make_unique<FibreTerm>(); }},
      {"drag", [] { return std::make_unique<Drag>(); }},
      {"maxwell", [] { return std::make_unique<MaxwellBranch>(); }},
  };
  return f;
}

}  // namespace

std::unique_ptr<Material> create_builtin_material(const std::string& name) {
  auto it = factories().find(name);
  return it == factories().end() ? nullptr : it->second();
}

std::unique_ptr<Material> create_material(const std::string& name, const std::string& plugin_path) {
  if (!plugin_path.empty()) return load_plugin_material(plugin_path, name);
  auto m = create_builtin_material(name);
  if (!m) throw Error("unknown material model '" + name + "'");
  return m;
}

std::vector<std::string> builtin_material_names() {
  std::vector<std::string> names;
  for (const auto& [name, f] : factories()) names.push_back(name);
  return names;
}

}  // namespace kelvin
