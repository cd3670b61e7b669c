#pragma once
/// \file
/// A relaxing branch (a Maxwell element in Green strain; one term of a Prony series,
/// the standard linear solid when added to an elastic term):
///   S = 2g (E − Z),  P = F S,  Ż = (E − Z)/τ,  E = ½ (FᵀF − I),
/// Z the branch's viscous strain, six internal variables per element
/// (Z₁₁, Z₂₂, Z₃₃, Z₁₂, Z₁₃, Z₂₃), integrated with the motion. Held at a strain, its
/// stress decays as e^(−t/τ); at a rate much faster than 1/τ it stiffens the body as
/// a St. Venant–Kirchhoff term of shear modulus g (λ = 0), much slower it damps like
/// a Newtonian viscosity ν = gτ (S = 2gτ Ė) and then vanishes. A body starts with it relaxed (Z =
/// E). Nested at g = 0. Several terms with different τ make a Prony series. (g, not μ: a nominal
/// model's `elastic.mu` stays unambiguous when a branch is added.)
#include "materials/material.hpp"

namespace kelvin {

class MaxwellBranch final : public Material {
 public:
  std::string name() const override { return "maxwell"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return false; }
  /// P = ∂Ψ/∂F at fixed Z for Ψ = g ‖E − Z‖².
  bool has_energy() const override { return true; }
  int internal_size() const override { return 6; }
  void relaxed_internal(const Mat3& F, const double* q, double* z) const override;
  void evolve(const MaterialPoint& in, unsigned request, InternalResponse& out) const override;
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;
};

}  // namespace kelvin
