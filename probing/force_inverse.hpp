#pragma once
/// \file
/// The force-based inverse of static probing (Bächer 2008, §5.2): with the
/// equilibrium positions x̄ of every node measured, the resisting force of an
/// elastic law linear in its parameters is linear in them,
///   r(x̄; θ) = Σ_e V_e P_e(F_e; q_e) G_e = A(x̄) θ,
/// so the parameters solve the linear least-squares problem A(x̄) θ = f̄ (the
/// measurement's loads: the probe, gravity) stacked over the measurements, with the
/// spatial smoothness γ_s L_s (differences across shared faces, Eq. 5.26) and, for
/// one parameter set per measurement, the smoothness γ_m L_m across measurements
/// (§5.2.2). A probe pressed to a depth holds its nodes: their rows are unknown,
/// and its measured force (ClampReaction) adds the sum of them instead. Solved by
/// SuiteSparseQR; γ_s from the corner of the L-curve.
/// Kelvin's corotational material is Müller's warped stiffness
/// K_e = R (λ_e C_e + μ_e D_e) Rᵀ (Eq. 5.14); any law linear in its parameters
/// (neo-Hookean, Mooney–Rivlin, StVK) works the same way.
#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

#include "engine/fem_model.hpp"
#include "probing/probing_system.hpp"

namespace kelvin {

/// One static measurement as the inverse sees it: the model under this
/// measurement's loads and supports (clamps), and the measured equilibrium
/// positions of every node (clamped ones at their pose).
struct StaticState {
  const FemModel* model = nullptr;
  Eigen::Matrix3Xd x;
  /// Pressed probes whose force was measured: (the model's clamp index, R̄ in N); each
  /// adds the three rows Σ_held A θ = R̄ + the held nodes' weight.
  std::vector<std::pair<int, Eigen::Vector3d>> reactions = {};
};

struct ForceInverseOptions {
  ElementGrouping grouping = ElementGrouping::kElement;
  /// One parameter set per measurement (for blending), tied by γ_m L_m.
  bool per_measurement = false;
  /// γ_s relative to the typical column of A (dimensionless); < 0: the L-curve's
  /// corner over `lcurve`.
  double gamma_space = -1;
  double gamma_measurement = 1e-2;  // relative, like γ_s
  std::vector<double> lcurve;       // γ_s grid; empty: 10^-6 … 10^1 in half decades
};

struct LCurvePoint {
  double gamma = 0;
  double residual = 0;   // ‖A θ − f̄‖ (N)
  double roughness = 0;  // ‖L_s θ‖ (parameter units)
};

struct ForceInverseResult {
  std::vector<std::string> parameters;  // the elastic term's, in its order
  /// Per parameter set (one, or one per measurement): parameters × elements.
  std::vector<Eigen::MatrixXd> q;
  double gamma_space = 0;        // the γ_s used
  double relative_residual = 0;  // ‖A θ − f̄‖ / ‖f̄‖
  std::vector<LCurvePoint> lcurve;
};

/// The fitted parameters of the models' one elastic term (viscous terms carry no
/// static load). Throws kelvin::Error when the measurements do not share a mesh
/// and material, a clamp is compliant, the term is not linear in its parameters
/// (naming the element where it is not), or the least-squares solve fails.
ForceInverseResult force_based_inverse(const std::vector<StaticState>& measurements,
                                       const ForceInverseOptions& options = {});

/// Young's modulus and Poisson's ratio of Lamé parameters (λ, μ).
double youngs_modulus(double lambda, double mu);
double poissons_ratio(double lambda, double mu);

}  // namespace kelvin
