#pragma once
/// \file
/// The unnamed effect (Wang, Kry et al.'s learned correction): when no named
/// candidate explains the gap, a compact correction of the stress, nested at zero,
/// is added to the nominal material and fitted with the adjoint like any candidate:
///  - elastic: the separable principal-stretch spline of materials/spline_material
///    with every knot value 0 (no stress) and the values at the stretch and volume
///    knots within ±20 % of the rest state free: a correction as a function of the
///    principal stretches and J;
///  - rate: a strain-dependent viscosity (materials/strain_damping) with d0 = d1 =
///    d2 = 0 and d1, d2 free (d0 too when the nominal has no Newtonian term, which
///    otherwise carries it): extra damping that grows with the largest stretch.
/// Its signature, read from the refitted values, says where in strain and rate the
/// nominal model is wrong.
#include <string>
#include <vector>

#include "diagnose/candidates.hpp"
#include "diagnose/named_value.hpp"

namespace kelvin {

/// The correction as a candidate (id "unnamed") for `scenario`'s nominal material.
Candidate learned_correction(const Scenario& scenario);

/// One point of the correction's signature.
struct SignaturePoint {
  std::string kind;  // "stretch" (f′ at a principal stretch), "volume" (h′ at J), "damping"
  double at = 1;     // the stretch, volume ratio or largest stretch
  double value = 0;  // the correction there: Pa (stretch, volume) or Pa s (damping)
  double std_error = NAN;
  /// Relative to the nominal: value / (M |at − 1|) for the elastic points (M the
  /// nominal's largest modulus: the correction's share of a linear stress there),
  /// value / ν for damping (ν the nominal viscosity; NAN without one).
  double relative = NAN;
};

struct CorrectionSignature {
  std::vector<SignaturePoint> points;
  std::string summary;  // e.g. "stiffer in tension (+12 % at 1.1), ..." for the report
};

/// The signature of a refit of learned_correction(scenario) from its fitted
/// parameters (labels `elastic[k].fN`, `elastic[k].hN`, `viscous[k].dN`).
CorrectionSignature correction_signature(const Scenario& scenario,
                                         const std::vector<NamedValue>& fitted);

}  // namespace kelvin
