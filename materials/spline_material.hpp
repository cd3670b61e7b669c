#pragma once
/// \file
/// Isotropic hyperelastic material designed by splines in the principal stretches
/// (Xu, Sin, Zhu & Barbič 2015, "Nonlinear material design using principal
/// stretches", ACM TOG 34(4)), in the separable form
///   Ψ(F) = Σᵢ f(σᵢ) + h(J),   J = σ₁σ₂σ₃ = det F,
///   pᵢ = ∂Ψ/∂σᵢ = f'(σᵢ) + h'(J) J/σᵢ,   P = U diag(p) Vᵀ.
/// f' and h' are C¹ cubic Hermite splines over fixed knots (stretch_knots(),
/// volume_knots() below). The parameters are their values at the knots (f1..fK for
/// f', h1..hM for h'; units of stress); knot slopes are fourth-order (five-knot) finite
/// differences of those values, so f', h', Ψ and P are all linear in the
/// parameters. Beyond the outer knots the splines continue linearly with the end
/// slope. f and h are the exact integrals of the cubics with f(1) = h(1) = 0, so
/// Ψ(I) = 0; the rest state is stress free iff f'(1) + h'(1) = 0.
/// The tangent uses the principal-stretch formula (materials/svd_utils.hpp) with the
/// divided difference (pᵢ − pⱼ)/(σᵢ − σⱼ) =
///   [f'(σᵢ) − f'(σⱼ)]/(σᵢ − σⱼ) − h'(J) σₖ,
/// whose first term falls back to f''(midpoint) when |σᵢ − σⱼ| < 1e-6 (error
/// O(|σᵢ − σⱼ|² f''') there).
/// f'' and h'' jump at the knots (the splines are C¹, not C²), so the tangent is
/// one-sided there (the interval to the right of a knot is used) and a finite
/// difference straddling a knot does not reproduce it.
/// det F ≤ 0 is inadmissible (h is a function of J > 0 by construction).
/// neo_hookean_values() gives the parameters that reproduce "neo-hookean":
///   f'(σ) = μ (σ − 1/σ),  h'(J) = λ/2 (J − 1/J)
/// (exact at the knots, interpolated in between); the defaults are those for
/// λ = μ = 1e4 Pa.
#include "materials/material.hpp"

namespace kelvin {

class SplineMaterial final : public Material {
 public:
  std::string name() const override { return "spline"; }
  const std::vector<ParamInfo>& params() const override;
  bool is_viscous() const override { return false; }
  bool has_energy() const override { return true; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override;

  static const std::vector<double>& stretch_knots();
  static const std::vector<double>& volume_knots();
  /// Parameter values (f1..fK, h1..hM) matching neo-hookean with these Lamé parameters.
  static std::vector<double> neo_hookean_values(double lambda, double mu);
};

}  // namespace kelvin
