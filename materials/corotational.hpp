#pragma once
/// \file
/// Corotational linear elasticity (Müller & Gross 2004; the "nominal" model of
/// Wang, Kry et al.; McAdams et al. 2011, "Efficient elasticity for character
/// skinning with contact and collisions"; Sifakis & Barbič 2012 course notes §5):
///   F = R S (polar decomposition, R a proper rotation),
///   Ψ = μ ‖S − I‖² + λ/2 tr(S − I)²,   P = R (2μ (S − I) + λ tr(S − I) I).
/// Written in the principal stretches of the sign-fixed SVD F = U Σ Vᵀ (R = U Vᵀ,
/// S = V Σ Vᵀ):  Ψ = μ Σᵢ (σᵢ − 1)² + λ/2 (Σᵢ σᵢ − 3)²,  pᵢ = 2μ(σᵢ − 1) + λ(Σσ − 3),
/// which gives the exact tangent from the principal-stretch formula of
/// materials/svd_utils.hpp (equivalent to differentiating R through the polar
/// decomposition; the divided difference (pᵢ − pⱼ)/(σᵢ − σⱼ) = 2μ is exact, so
/// repeated stretches are harmless).
/// λ, μ are the small-strain Lamé parameters. Inverted elements (det F < 0) are
/// evaluated with σ₃ < 0; the tangent is singular where σᵢ + σⱼ = 0 (the rotation
/// is not defined there), and such states are reported inadmissible.
#include "materials/material.hpp"

namespace kelvin {

class Corotational final : public Material {
 public:
  std::string name() const override { return "corotational"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return false; }
  bool has_energy() const override { return true; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;
};

}  // namespace kelvin
