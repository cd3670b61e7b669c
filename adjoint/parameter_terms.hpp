#pragma once
/// \file
/// The terms of a fit's objective that depend on the parameters alone, beside the
/// simulated ones (marker misfit, shape targets, static measurements): the
/// smoothness of per-element fields, the Gaussian priors of parameters with a
/// penalty, and the penalty on falling spline stress curves (Real2Sim §4: a
/// spline material whose stress falls with stretch is unstable). Each is a value
/// in Φ's unit (m² s) at the optimiser-space p with its gradient there.
#include <Eigen/Core>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "adjoint/parameter_map.hpp"
#include "engine/fem_model.hpp"

namespace kelvin {

class ParameterTerm {
 public:
  virtual ~ParameterTerm() = default;
  virtual std::string name() const = 0;
  /// The term at p; adds its gradient to *g when given.
  virtual double value(const Eigen::VectorXd& p, Eigen::VectorXd* g) const = 0;
};

/// γ Σ (p_a − p_b)² over entries of per-element blocks whose elements share a face
/// (Bächer 2008, Eq. 5.26): in optimiser space, so log fields are smoothed in log.
class SmoothnessTerm final : public ParameterTerm {
 public:
  SmoothnessTerm(const ParameterMap& map, const Mesh& mesh, double gamma);
  std::string name() const override { return "smoothness"; }
  double value(const Eigen::VectorXd& p, Eigen::VectorXd* g) const override;
  /// Σ (p_a − p_b)² without γ: the L-curve's roughness axis.
  double roughness(const Eigen::VectorXd& p) const;

 private:
  std::vector<std::pair<int, int>> pairs_;
  double gamma_;
};

/// Σ_blocks penalty Σⱼ (pⱼ/scale)² (FitParameterSpec::penalty).
class PriorTerm final : public ParameterTerm {
 public:
  explicit PriorTerm(const ParameterMap& map) : map_(map) {}
  std::string name() const override { return "priors"; }
  double value(const Eigen::VectorXd& p, Eigen::VectorXd* g) const override;

 private:
  const ParameterMap& map_;
};

/// w Σ_e (V_e/V) Σ_k min(0, q_{k+1}(e) − q_k(e))² over consecutive knots of the
/// spline material's f' and h' (materials/spline_material.hpp) where at least one
/// of the two is fitted: zero while both curves rise, a quadratic wall where one
/// falls. Knots that are not fitted keep the model's values.
class SplineSlopeTerm final : public ParameterTerm {
 public:
  /// `weight` in m² s per Pa² of fall.
  SplineSlopeTerm(const ParameterMap& map, const FemModel& model, double weight);
  std::string name() const override { return "spline slopes"; }
  double value(const Eigen::VectorXd& p, Eigen::VectorXd* g) const override;
  /// Consecutive knot pairs the term watches (0: nothing to penalise).
  int pairs() const { return static_cast<int>(pairs_.size()); }

 private:
  struct Knot {
    int term = 0, index = 0;
    std::vector<int> slots;  // the map's blocks of this knot (a value block, multipliers)
  };
  const ParameterMap& map_;
  const FemModel& model_;
  double weight_;
  std::vector<std::pair<Knot, Knot>> pairs_;
  Eigen::VectorXd volume_share_;  // V_e / V
  double knot(const Knot& k, const Eigen::VectorXd& p, int e) const;
};

/// The parameter terms of a fit: smoothness when γ > 0, priors when a block has
/// a penalty, spline slopes when `spline_slope_penalty` > 0 and a spline knot is fitted.
std::vector<std::unique_ptr<ParameterTerm>> parameter_terms(const ParameterMap& map,
                                                            const FemModel& model, double gamma,
                                                            double spline_slope_penalty);

}  // namespace kelvin
