#pragma once
/// \file
/// Compressible neo-Hookean solid in the form used by Real2Sim (Hahn et al. 2019):
///   Ψ(F) = λ/2 ((J² − 1)/2 − ln J) + μ/2 (tr FᵀF − 3 − 2 ln J),   J = det F
///   P    = λ/2 (J² − 1) F⁻ᵀ + μ (F − F⁻ᵀ)
/// Lamé parameters λ, μ agree with linear elasticity at small strain.
#include "materials/material.hpp"

namespace kelvin {

class NeoHookean final : public Material {
 public:
  std::string name() const override { return "neo-hookean"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return false; }
  bool has_energy() const override { return true; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;
};

}  // namespace kelvin
