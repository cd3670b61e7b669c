#pragma once
/// \file
/// Compressible Mooney–Rivlin solid with a decoupled (isochoric/volumetric) energy
/// (Mooney 1940, Rivlin 1948; decoupled form as in Holzapfel 2000, §6.5):
///   Ψ = C10 (Ī₁ − 3) + C01 (Ī₂ − 3) + κ/2 (J − 1)²
///   Ī₁ = J^(−2/3) I₁,  Ī₂ = J^(−4/3) I₂,  I₁ = tr C,  I₂ = ½ (I₁² − tr C²),  C = FᵀF
///   P  = C10 J^(−2/3) (2F − ⅔ I₁ F⁻ᵀ) + C01 J^(−4/3) (2(I₁F − FC) − ⁴⁄₃ I₂ F⁻ᵀ)
///        + κ (J − 1) J F⁻ᵀ
/// Small-strain equivalence: shear modulus μ = 2 (C10 + C01), bulk modulus κ, so
/// λ = κ − 2μ/3. The isochoric invariants need J > 0: det F ≤ 0 is inadmissible.
/// Tangents are exact (forward-mode AD).
#include "materials/material.hpp"

namespace kelvin {

class MooneyRivlin final : public Material {
 public:
  std::string name() const override { return "mooney-rivlin"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return false; }
  bool has_energy() const override { return true; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;
};

}  // namespace kelvin
