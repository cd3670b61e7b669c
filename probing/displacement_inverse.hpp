#pragma once
/// \file
/// The displacement-based inverse of static probing (Bächer 2008, §5.3, Eq. 5.67):
/// minimise over the fitted values θ (in log space: moduli stay positive)
///   Φ = ½ Σ_m Σ_j ‖x_j(θ) − x̄_mj‖² + ½ γ² S ‖L log θ‖² / n_L,
/// x(θ) the static equilibrium of measurement m, x_j its marker positions (plus, for
/// a probe pressed to a depth with its force measured, ½ c ‖R(θ) − R̄‖²), S the
/// data's own size Σ ‖x̄ − X‖² (so γ = 1 prices a unit log-jump across every face
/// like not deforming at all) and n_L the rows of L. The gradient comes from the
/// adjoint of each equilibrium: K λ = Σ_j w_jᵀ (x_j − x̄_j), dΦ/dθ = −λᵀ ∂r/∂θ (one
/// solve with the already assembled K per measurement). Unlike the force-based
/// inverse it needs no position of unobserved nodes and any elastic law, and noise
/// in the markers stays in the residual instead of entering the system matrix.
#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

#include "engine/fem_model.hpp"
#include "engine/markers.hpp"
#include "probing/probing_system.hpp"

namespace kelvin {

/// One static measurement: the model under its loads and supports (its elastic
/// term's parameters are overwritten during the fit) and the markers' measured
/// loaded positions.
struct ObservedProbe {
  FemModel* model = nullptr;
  std::vector<MarkerEmbedding> markers;
  Eigen::Matrix3Xd observed;  // 3 × markers (m); a non-finite column is occluded
  /// Pressed probes whose force was measured: (the model's clamp index, R̄ in N). Each
  /// adds ½ reaction_weight ‖R − R̄‖² to the marker misfit, R its ClampReaction.
  std::vector<std::pair<int, Eigen::Vector3d>> reactions;
  double reaction_weight = 0;  // m²/N²: (marker noise / force noise)²
};

struct DisplacementInverseOptions {
  ElementGrouping grouping = ElementGrouping::kGlobal;
  double gamma_space = 0;  // see the file comment; only with kElement
  int max_evaluations = 300;
  double relative_tolerance = 1e-12;  // on Φ (NLopt's ftol_rel)
};

struct DisplacementInverseResult {
  std::vector<std::string> parameters;  // the elastic term's, in its order
  Eigen::MatrixXd q;                    // parameters × elements
  double rms = 0;                       // marker distance over all measurements (m)
  double reaction_rms = 0;              // measured reactions' misfit per component (N)
  int evaluations = 0;
  std::string stop;  // why the optimiser stopped
};

/// Starts from the first model's parameters (averaged over each group). Throws
/// kelvin::Error when a fitted parameter may be ≤ 0, a measurement observes
/// nothing, or the start has no equilibrium; a trial without one is a failed trial
/// the line search backs off from (`stop` counts them).
DisplacementInverseResult displacement_based_inverse(
    std::vector<ObservedProbe>& measurements, const DisplacementInverseOptions& options = {});

}  // namespace kelvin
