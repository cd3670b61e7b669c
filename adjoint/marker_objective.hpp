#pragma once
/// \file
/// The marker misfit of Real2Sim Eq. 15,
///   Φ = ½ ∫ Σᵢ wᵢ ‖x*ᵢ(t) − x̄ᵢ(t)‖² dt   over the window [t₀, t₁],
/// with x*ᵢ the simulated marker (barycentric in its tet) and x̄ᵢ the observed track,
/// a not-a-knot cubic spline through each run of consecutive frames in which the marker was seen.
/// Interval rule for occlusion: marker i contributes on [t_k, t_k+1] only when it was seen in both
/// frames k and k+1; elsewhere (and outside the frames' span) its integrand is zero, never an
/// extrapolation. One quadrature component per marker, so per-marker errors come for free.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "engine/csv.hpp"
#include "engine/fem_model.hpp"
#include "engine/markers.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {

class MarkerObjective {
 public:
  /// Markers without an observed track are ignored. Throws kelvin::Error when no
  /// marker is observed inside the window.
  MarkerObjective(const std::vector<MarkerEmbedding>& markers, const MarkerTracks& observed,
                  const ObjectiveSpec& spec, double t_end);

  int num_markers() const { return static_cast<int>(names_.size()); }
  const std::vector<std::string>& names() const { return names_; }
  double window_begin() const { return t0_; }
  double window_end() const { return t1_; }

  /// gᵢ(t) = ½ wᵢ ‖x*ᵢ − x̄ᵢ‖² for each marker (0 where unobserved); x is the full
  /// nodal position field of `model`.
  void integrand(double t, const FemModel& model, const Eigen::Matrix3Xd& x, double* g) const;
  /// ∂(Σᵢ gᵢ)/∂x over the free dofs, added to grad.
  void add_gradient(double t, const FemModel& model, const Eigen::Matrix3Xd& x, double* grad) const;

  /// ∫ wᵢ dt over marker i's observed intervals in the window: RMSᵢ = sqrt(2Φᵢ / this).
  double weighted_observed_time(int i) const { return weighted_time_[i]; }
  /// Per-marker RMS distances and the overall one, sqrt(2Φ / Σᵢ wᵢTᵢ) — for full
  /// observation and unit weights Real2Sim's sqrt(2Φ/(N T)).
  Eigen::VectorXd marker_rms(const Eigen::VectorXd& phi_per_marker) const;
  double rms(const Eigen::VectorXd& phi_per_marker) const;

 private:
  /// Observed position of marker i at t; false when unobserved there.
  bool observed(int i, double t, Eigen::Vector3d& xbar) const;

  std::vector<std::string> names_;
  std::vector<MarkerEmbedding> embedding_;
  std::vector<double> weight_, weighted_time_;
  std::vector<double> times_;
  std::vector<Eigen::Matrix3Xd> track_;   // per marker 3 × frames (NaN = occluded)
  std::vector<Eigen::Matrix3Xd> slopes_;  // the spline's velocity at each seen frame
  double t0_ = 0, t1_ = 0;
};

}  // namespace kelvin
