#pragma once
/// \file
/// Saint Venant–Kirchhoff solid (e.g. Holzapfel 2000, "Nonlinear Solid Mechanics",
/// §6.5): linear isotropic elasticity in the Green–Lagrange strain,
///   E = ½ (FᵀF − I),  Ψ = μ E:E + λ/2 (tr E)²,  P = F (2μ E + λ tr E I).
/// λ, μ are the small-strain Lamé parameters. The model is defined for every F but
/// softens and loses stability under strong compression (P → 0 as F → 0), so it
/// never reports a state inadmissible. Tangents are exact (forward-mode AD).
#include "materials/material.hpp"

namespace kelvin {

class StVenantKirchhoff final : public Material {
 public:
  std::string name() const override { return "stvk"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return false; }
  bool has_energy() const override { return true; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;
};

}  // namespace kelvin
