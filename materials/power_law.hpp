#pragma once
/// \file
/// Viscous stresses in the spatial frame, pulled back to first Piola–Kirchhoff:
///   L = Ḟ F⁻¹,  d = L + Lᵀ,  γ̇ = sqrt(1/2) ‖d‖_F
///   power-law (Real2Sim, Hahn et al. 2019):  σ = ν γ̇^(h−1) d
///   Newtonian:                               σ = ν d
///   P = J σ F⁻ᵀ
/// Following Real2Sim, a material point whose velocity gradient has norm ≤ DBL_MIN
/// contributes nothing (the power law is singular at rest for h < 1).
/// Tangents dP/dF, dP/dḞ and dP/dq are exact, by forward-mode automatic
/// differentiation of the same expression (Eigen's AutoDiffScalar).
#include "materials/material.hpp"

namespace kelvin {

class PowerLawViscosity final : public Material {
 public:
  std::string name() const override { return "power-law"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return true; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;
};

class NewtonianViscosity final : public Material {
 public:
  std::string name() const override { return "newtonian"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return true; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;
};

}  // namespace kelvin
