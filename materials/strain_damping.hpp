#pragma once
/// \file
/// Strain-dependent Newtonian damping (after Wang, Kry et al., whose damping grows
/// with the largest principal stretch): the "newtonian" stress of
/// materials/power_law.hpp with a viscosity that depends on the deformation,
///   P = ν(σ_max) J (L + Lᵀ) F⁻ᵀ,   L = Ḟ F⁻¹,
///   ν(σ) = d0 + d1 (σ − 1) + d2 (σ − 1)²,   σ_max = largest singular value of F.
/// dP/dF includes ∂σ_max/∂F = u₁ v₁ᵀ (top singular pair). σ_max is not
/// differentiable where the two largest singular values coincide (e.g. F = I or a
/// uniaxial compression); there the tangent uses one arbitrary pair from the SVD and
/// is only a subgradient. ν is not clamped: d1, d2 < 0 can make it negative (the
/// user's responsibility). With d1 = d2 = 0 this is exactly "newtonian" with ν = d0.
#include "materials/material.hpp"

namespace kelvin {

class StrainDamping final : public Material {
 public:
  std::string name() const override { return "strain-damping"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return true; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;
};

}  // namespace kelvin
