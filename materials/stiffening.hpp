#pragma once
/// \file
/// A Yeoh-like stiffening term to add to an elastic model:
///   Ψ = c₂ (I₁ − 3 − 2 ln J)²,   P = 4 c₂ (I₁ − 3 − 2 ln J) (F − F⁻ᵀ),
/// zero at rest and to second order in the strain, so it changes only large
/// deformations; c₂ = 0 is the model without it (the diagnosis's nested extension).
/// Tangents are exact (forward-mode AD).
#include "materials/material.hpp"

namespace kelvin {

class Stiffening final : public Material {
 public:
  std::string name() const override { return "stiffening"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return false; }
  bool has_energy() const override { return true; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;
};

}  // namespace kelvin
