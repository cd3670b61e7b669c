#pragma once
/// \file
/// The marker misfit of Real2Sim Eq. 15,
///   Φ = ½ ∫ Σᵢ wᵢ ‖x*ᵢ(t) − x̄ᵢ(t)‖² dt   over the window [t₀, t₁],
/// with x*ᵢ the simulated marker (barycentric in its tet) and x̄ᵢ the observed track,
/// a not-a-knot cubic spline through each run of consecutive frames in which the marker was seen.
/// Interval rule for occlusion: marker i contributes on [t_k, t_k+1] only when it was seen in both
/// frames k and k+1; elsewhere (and outside the frames' span) its integrand is zero, never an
/// extrapolation. One quadrature component per marker, so per-marker errors come for free.
/// A clock offset reads each run's spline at t + τ; where that falls past the run's
/// ends, the residual counts with a weight c that falls smoothly from 1 to 0 within
/// one frame interval (the counted residual is c (x* − x̄)), so Φ stays smooth in τ
/// and never compares with a track extrapolated far past what was seen. The
/// intervals that count are those of τ = 0 at every τ (some with weight 0). Frame-by-
/// frame residuals (sample_pair) instead compare each captured frame with the model
/// at t − τ.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "engine/csv.hpp"
#include "engine/fem_model.hpp"
#include "engine/markers.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {

/// How the capture relates to the model, all zero in the nominal model (each is a
/// nested extension of the gap diagnosis): a clock offset τ (the marker clock runs
/// ahead of the clamp's: Φ compares the model at t with the tracks at t + τ, a frame
/// residual the captured frame at t with the model at t − τ), an
/// offset δᵢ of each marker's rest position (rest frame, m), and a rigid
/// registration of the capture frame: x̄ ↦ R(ω)(x̄ − c) + c + d, R(ω) = exp([ω]×),
/// c the mean of the captured positions.
struct ObservationParams {
  double clock_offset = 0;          // s
  Eigen::Matrix3Xd marker_offsets;  // 3 × markers; empty = none
  Eigen::Vector3d rotation = Eigen::Vector3d::Zero(), translation = Eigen::Vector3d::Zero();
};

class MarkerObjective {
 public:
  /// Markers without an observed track are ignored. Throws kelvin::Error when no
  /// marker is observed inside the window, unless `may_be_empty` (an objective of
  /// shape targets alone).
  MarkerObjective(const std::vector<MarkerEmbedding>& markers, const MarkerTracks& observed,
                  const ObjectiveSpec& spec, double t_end, bool may_be_empty = false);

  int num_markers() const { return static_cast<int>(names_.size()); }
  const std::vector<std::string>& names() const { return names_; }
  double window_begin() const { return t0_; }
  double window_end() const { return t1_; }

  /// gᵢ(t) = ½ wᵢ ‖x*ᵢ − x̄ᵢ‖² for each marker (0 where unobserved); x is the full
  /// nodal position field of `model`.
  void integrand(double t, const FemModel& model, const Eigen::Matrix3Xd& x, double* g) const;
  /// ∂(Σᵢ gᵢ)/∂x over the free dofs, added to grad.
  void add_gradient(double t, const FemModel& model, const Eigen::Matrix3Xd& x, double* grad) const;

  /// The observation parameters in use (zero unless set).
  const ObservationParams& observation() const { return obs_; }
  void set_observation(const ObservationParams& params);
  /// Entries of the observation vector θ: clock offset, 3 per marker (offsets, in
  /// names() order), then rotation (3) and translation (3).
  int num_observation_parameters() const { return 7 + 3 * num_markers(); }
  /// θ as a vector and back (the layout above).
  Eigen::VectorXd observation_vector() const;
  void set_observation_vector(const Eigen::VectorXd& theta);
  /// ∂(Σᵢ gᵢ)/∂θ at t, written to out (num_observation_parameters() entries), the
  /// residual weight's dependence on τ included.
  void observation_gradient(double t, const FemModel& model, const Eigen::Matrix3Xd& x,
                            double* out) const;
  /// Φ's pairing at model time t: marker i's simulated position (its offset applied),
  /// the observed one as the model sees it at t (the track at t + τ) and, on request,
  /// the weight c ∈ [0, 1] of its residual (below 1 only where a clock offset reads
  /// past the ends of the run seen around t); false when it does not count at t.
  bool marker_pair(int i, double t, const FemModel& model, const Eigen::Matrix3Xd& x,
                   Eigen::Vector3d& simulated, Eigen::Vector3d& observed,
                   double* presence = nullptr) const;

  /// The model time at which a sample of the capture at t is compared: t − τ. The
  /// frame-by-frame residuals (standard errors, likelihood ratios, held-out checks)
  /// move the model, never the capture: a track read between its frames averages
  /// their noise (a cubic spline a third of a frame off keeps 80 % of its variance,
  /// half a frame off 75 %), which would credit any clock offset with a misfit drop
  /// of up to a quarter of the noise. A model time outside the run is held at its
  /// first state (the body at rest before a static or resting start) or its last
  /// (past the end: a stand-in that charges a negative offset its last |τ| of frames).
  double model_time(double t) const { return t - obs_.clock_offset; }
  /// Marker i as a frame-by-frame residual compares it: the simulated position from
  /// x, the model at model_time(t) (its offset applied), and the capture at t
  /// itself, registered; false when the marker does not count at t (the rule of Φ's
  /// intervals at τ = 0).
  bool sample_pair(int i, double t, const FemModel& model, const Eigen::Matrix3Xd& x,
                   Eigen::Vector3d& simulated, Eigen::Vector3d& observed) const;
  /// d(x*ᵢ − x̄'ᵢ)/dθ of sample_pair (3 × num_observation_parameters()): the clock's
  /// column is −ẋ*ᵢ (v the model's velocities at model_time(t)), 0 where the model
  /// time was held at an end of the run (`clock_moves` false); zero where marker i
  /// does not count. What the Gauss–Newton system needs beside d x*/dp.
  Eigen::Matrix3Xd sample_jacobian(int i, double t, const FemModel& model,
                                   const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v,
                                   bool clock_moves) const;
  /// Barycentric weights of marker i with its offset applied, and its tet.
  Eigen::Vector4d weights(int i, const FemModel& model) const;
  int tet(int i) const { return embedding_[i].tet; }
  /// The weight wᵢ of marker i in Φ.
  double weight(int i) const { return weight_[i]; }

  /// ∫ wᵢ dt over marker i's observed intervals in the window: RMSᵢ = sqrt(2Φᵢ / this).
  double weighted_observed_time(int i) const { return weighted_time_[i]; }
  /// Per-marker RMS distances sqrt(2Φᵢ / wᵢTᵢ) — for full observation and unit
  /// weights Real2Sim's sqrt(2Φ/(N T)). The overall one, with the shape targets,
  /// is Experiment::rms.
  Eigen::VectorXd marker_rms(const Eigen::VectorXd& phi_per_marker) const;

 private:
  /// Observed position of marker i at t in the capture's own frame and clock, and
  /// on request its time derivative and the residual's weight c with dc/dτ; false
  /// when unobserved there.
  bool observed(int i, double t, double offset, Eigen::Vector3d& xbar,
                Eigen::Vector3d* rate = nullptr, double* presence = nullptr,
                double* presence_rate = nullptr) const;
  /// d(c (x*ᵢ − x̄'ᵢ))/dθ of Φ's pairing at model time t, zero where marker i does
  /// not count: Φ's gradient in θ.
  Eigen::Matrix3Xd pair_jacobian(int i, double t, const FemModel& model,
                                 const Eigen::Matrix3Xd& x) const;
  /// marker_pair and sample_pair: the capture read at t + offset.
  bool pair(int i, double t, double offset, const FemModel& model, const Eigen::Matrix3Xd& x,
            Eigen::Vector3d& simulated, Eigen::Vector3d& observed,
            double* presence = nullptr) const;
  /// The registered capture R(x̄ − c) + c + d.
  Eigen::Vector3d registered(const Eigen::Vector3d& xbar) const;
  /// Simulated position of marker i in x (its offset applied).
  Eigen::Vector3d simulated(int i, const FemModel& model, const Eigen::Matrix3Xd& x) const;
  /// The columns of d(x* − x̄')/dθ other than the clock's: offsets and registration.
  void offset_and_registration_columns(int i, const FemModel& model, const Eigen::Matrix3Xd& x,
                                       const Eigen::Vector3d& xbar, Eigen::Matrix3Xd& J) const;
  std::vector<std::string> names_;
  std::vector<MarkerEmbedding> embedding_;
  std::vector<double> weight_, weighted_time_;
  std::vector<double> times_;
  std::vector<Eigen::Matrix3Xd> track_;   // per marker 3 × frames (NaN = occluded)
  std::vector<Eigen::Matrix3Xd> slopes_;  // the spline's velocity at each seen frame
  double t0_ = 0, t1_ = 0;
  std::vector<std::vector<int>> run_first_, run_last_;  // per marker, per frame: its seen run
  Eigen::Vector3d centroid_ = Eigen::Vector3d::Zero();  // of the captured positions
  ObservationParams obs_;
  Eigen::Matrix3d R_ = Eigen::Matrix3d::Identity();   // R(obs_.rotation)
  Eigen::Matrix3d Jr_ = Eigen::Matrix3d::Identity();  // its right Jacobian J_r
};

}  // namespace kelvin
