#pragma once
/// \file
/// Stable neo-Hookean solid (Smith, de Goes & Kim 2018, "Stable Neo-Hookean Flesh
/// Simulation", ACM TOG 37(2), eq. 14 with the Lamé reparametrisation of §3.4):
///   Ψ(F) = μ'/2 (I_C − 3) + λ'/2 (J − α)² − μ'/2 ln(I_C + 1)
///   P    = μ' (1 − 1/(I_C + 1)) F + λ' (J − α) cof F
///   I_C = tr FᵀF,  J = det F,  cof F = ∂J/∂F,
///   μ' = 4μ/3,  λ' = λ + 5μ/6,  α = 1 + 3μ'/(4λ') (= 1 + μ'/λ' − μ'/(4λ')),
/// so that the rest state is stress free and the user's λ, μ are the small-strain
/// Lamé parameters (the same meaning as for "neo-hookean").
/// There is no ln J: the energy is finite and smooth for J ≤ 0, so inverted elements
/// are evaluated (and pushed back) rather than rejected — the point of the model.
/// Tangents are exact (forward-mode AD, materials/ad_stress.hpp).
#include "materials/material.hpp"

namespace kelvin {

class StableNeoHookean final : public Material {
 public:
  std::string name() const override { return "stable-neo-hookean"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return false; }
  bool has_energy() const override { return true; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;
};

}  // namespace kelvin
