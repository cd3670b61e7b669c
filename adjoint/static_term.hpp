#pragma once
/// \file
/// A static probing measurement as a term of a fit (Bächer 2008 next to captured
/// motion: the same specimen probed and shaken). Its misfit
///   Φ_s = w ½ Σ_j ‖x_j(q(p)) − x̄_j‖²,
/// x the equilibrium under the measurement's loads, weighs like w seconds of a
/// captured track of the same markers (Φ of a track is ½ ∫ ‖r‖² dt), so the fit's
/// RMS stays a distance. Its gradient comes from the adjoint of the equilibrium
/// R(x; q) = r(x) − f_ext = 0: K λ = w Σ_j W_jᵀ r_j, dΦ_s/dq = −λᵀ ∂R/∂q, one solve
/// with the tangent already assembled, chained through the fit's parameter map.
/// A pressed probe whose force R̄ was measured adds w ½ c ‖R − R̄‖² (c = (marker
/// noise / force noise)², engine/clamp_reaction.hpp): its position derivative joins
/// the adjoint's load, its parameter derivative is the held rows of ∂R/∂q.
#include <Eigen/Core>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "adjoint/parameter_map.hpp"
#include "engine/clamp_reaction.hpp"
#include "engine/fem_model.hpp"
#include "engine/markers.hpp"

namespace kelvin {

struct StaticTermResult {
  bool ok = false;
  std::string error;  // why there is no equilibrium (names the measurement)
  double phi = 0;
  double rms = 0;            // marker distance (m), 3-D
  Eigen::VectorXd gradient;  // dΦ_s/dp (empty without a gradient)
};

class StaticTerm {
 public:
  /// `model` (its loads: the scenario's plus the probe's) must outlive the term and
  /// share the fitted material models; `observed` is 3 × markers, NaN = occluded;
  /// the weight (s) may be set later.
  StaticTerm(FemModel& model, std::string name, std::vector<MarkerEmbedding> markers,
             Eigen::Matrix3Xd observed, double weight,
             std::vector<std::pair<int, Eigen::Vector3d>> reactions = {},
             double reaction_weight = 0);

  const std::string& name() const { return name_; }
  double weight() const { return weight_; }
  void set_weight(double w) { weight_ = w; }
  int observed_markers() const { return observed_count_; }
  int measured_reactions() const { return static_cast<int>(reactions_.size()); }
  FemModel& model() { return model_; }

  /// Φ_s and, when asked, dΦ_s/dp at p (applied to the model first). A trial without
  /// an equilibrium is reported, not thrown: the fitter backs off from it.
  StaticTermResult evaluate(const ParameterMap& map, const Eigen::VectorXd& p, bool gradient);

  /// For Gauss–Newton: the residuals x_j − x̄_j of the observed coordinates (NaN ones
  /// left out; `coordinates` gets (marker, axis) of each), then √c (R − R̄) of each
  /// measured reaction k (coordinates (−1 − k, axis)) and, when asked, their
  /// Jacobian dr/dp = −W K⁻¹ ∂R/∂p (one solve per parameter with one factorisation).
  /// False with `error` set when there is no equilibrium.
  bool residuals(const ParameterMap& map, const Eigen::VectorXd& p, bool with_jacobian,
                 Eigen::VectorXd& r, Eigen::MatrixXd& jacobian,
                 std::vector<std::pair<int, int>>& coordinates, std::string& error);

 private:
  FemModel& model_;
  std::string name_;
  std::vector<MarkerEmbedding> markers_;
  Eigen::Matrix3Xd observed_;
  double weight_;
  std::vector<std::pair<int, Eigen::Vector3d>> reactions_;  // (clamp, R̄)
  double reaction_weight_;
  int observed_count_ = 0;
  Eigen::VectorXd x_free_;  // the last equilibrium: the next trial's start

  /// Applies p and solves for the equilibrium (full positions into x); false with a
  /// message naming the measurement when there is none.
  bool equilibrium(const ParameterMap& map, const Eigen::VectorXd& p, Eigen::Matrix3Xd& x,
                   std::string& error);
  /// The tangent K over the free dofs at full positions x, factorised; false when
  /// singular or an element is inadmissible.
  bool factor_stiffness(const Eigen::Matrix3Xd& x, std::string& error);
  /// R − R̄ of each measured reaction at x; false with `error` set when a material
  /// rejects x.
  /// The message for a press whose elements a material rejects.
  std::string inadmissible(const ClampReaction& press) const;
  bool reaction_misfits(const Eigen::Matrix3Xd& x, std::vector<Eigen::Vector3d>& misfit,
                        std::string& error) const;
  std::function<Eigen::VectorXd(const Eigen::VectorXd&)> solve_;
};

}  // namespace kelvin
