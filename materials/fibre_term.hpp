#pragma once
/// \file
/// A fibre term to add to an isotropic elastic model, stiff in tension and
/// compression along one direction a (a unit vector in the rest frame):
///   Ψ = k/2 (I₄ − 1)²,   I₄ = ‖F a‖²,   P = 2k (I₄ − 1) F a aᵀ,
///   a = (sin θ cos φ, sin θ sin φ, cos θ).
/// The direction is two parameters, so it can be given or fitted with k; k = 0 is
/// the isotropic model (the diagnosis's nested extension). Tangents in closed form:
/// the diagnosis evaluates many such terms per element and step.
#include "materials/material.hpp"

namespace kelvin {

class FibreTerm final : public Material {
 public:
  std::string name() const override { return "fibre"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return false; }
  bool has_energy() const override { return true; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;
};

}  // namespace kelvin
