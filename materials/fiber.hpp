#pragma once
/// \file
/// Transversely isotropic fibre-reinforced solid after Holzapfel, Gasser & Ogden
/// 2000 ("A new constitutive framework for arterial wall mechanics", J. Elasticity
/// 61): the neo-Hookean matrix of materials/neo_hookean.hpp plus one fibre family
///   Ψ_f = k1/(2 k2) (exp(k2 (I₄ − 1)²) − 1)   for I₄ > 1, 0 otherwise,
///   I₄ = a·C a = |F a|²,  a = unit fibre direction in the reference configuration,
///   P_f = 2 ψ' F a aᵀ,  ψ' = k1 (I₄ − 1) exp(k2 (I₄ − 1)²).
/// Fibres carry no load in compression (as in HGO); Ψ_f is C¹ at I₄ = 1 since ψ'
/// vanishes there, but its second derivative jumps by 2k1, so the tangent is
/// discontinuous across I₄ = 1; exactly at I₄ = 1 (within rounding) the mean of
/// the one-sided tangents is returned. k2 → 0 gives the quadratic limit k1/2 (I₄ − 1)².
/// a is per-element state (3 values, normalised here; default (1, 0, 0), also used
/// when no state is given). Parameters: lambda, mu (matrix), k1 (Pa), k2 (1).
#include "materials/material.hpp"

namespace kelvin {

class FiberReinforced final : public Material {
 public:
  std::string name() const override { return "fiber"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return false; }
  bool has_energy() const override { return true; }
  int state_size() const override { return 3; }
  std::vector<double> default_state() const override { return {1, 0, 0}; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;
};

}  // namespace kelvin
