#pragma once
/// \file
/// Rayleigh damping, D = α₀ M + α₁ K₀ for small motions about the rest state.
///
/// The mass-proportional part α₀ M v is added by the engine (mass_damping_param).
/// The stiffness-proportional part is a Kelvin–Voigt stress on the Green strain
/// rate, driven by the elastic rest tangent C₀ = ∂P/∂F|_{F=I} of the same element:
///   Ė = sym(Fᵀ Ḟ),   S = α₁ C₀ : Ė,   P = F S
/// Linearised about rest it gives exactly α₁ K₀ v, so a mode of angular frequency
/// ω has the classical damping ratio ζ = α₀/(2ω) + α₁ω/2; unlike α₁ K₀ v it
/// vanishes under rigid rotation (Ė = 0), so a swinging body is not damped
/// spuriously. Every derivative is closed-form: ∂P/∂α₁ = F C₀:Ė, and C₀ is linear
/// in the elastic parameters for every built-in model, so its parameter
/// derivatives are exact too.
/// Standalone evaluation (check-material, no engine) uses the isotropic C₀ of
/// λ = μ = 1.
#include "materials/material.hpp"

namespace kelvin {

class RayleighDamping final : public Material {
 public:
  std::string name() const override { return "rayleigh"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return true; }
  bool needs_rest_tangent() const override { return true; }
  int mass_damping_param() const override { return 0; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;
};

}  // namespace kelvin
