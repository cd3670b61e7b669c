#pragma once
/// \file
/// Mass-proportional drag, the body force −c ρ v (air drag on a light body, or
/// Rayleigh's α₀ on its own): no stress, only the engine's α M v force with α = c
/// (mass_damping_param). c = 0 is the model without it (the diagnosis's nested
/// extension); add it next to any viscous model.
#include "materials/material.hpp"

namespace kelvin {

class Drag final : public Material {
 public:
  std::string name() const override { return "drag"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return true; }
  int mass_damping_param() const override { return 0; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;
};

}  // namespace kelvin
