#pragma once
/// \file
/// Blending of per-measurement parameter sets (Bächer 2008, ch. 6). A warped-linear
/// set fitted to one probe is right for the strains that probe made; a new contact
/// takes, per element, a blend of the sets whose strains were like its own:
///   q_e = exp Σ_m w_me log q_me,  w_me ∝ exp(−d_m(e)² / 2h²),  Σ_m w_me = 1,
/// a normalised Gaussian RBF in strain space, blended in log space so moduli stay
/// positive and a new contact never leaves the range the sets span. The distance:
/// - global (a homogeneous body): d_m = |s − s_m|, s the strain level of the whole
///   body, Σ V‖E‖³ / Σ V‖E‖² (the strain where the elastic energy is; it does not
///   depend on where the contact is nor on how much of the body stays at rest);
/// - local (an inhomogeneous body, Eq. 6.11): d_m(e)² the Gaussian-weighted mean of
///   ‖E_j − E_mj‖² over the elements j near e, so each element takes the sets that
///   strained its own neighbourhood as it is strained now.
/// h is the sets' own spacing in that distance (median nearest-neighbour distance).
/// The weights depend on the strain and the strain on the weights: the contact is
/// loaded in increments, the weights of each from the strain of the one before,
/// then passes at the full load, each halfway to the weights the strain asks for,
/// until they settle.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "engine/fem_model.hpp"

namespace kelvin {

/// Green–Lagrange strain of every element at full positions x: 6 × elements, as
/// (E11, E22, E33, √2 E23, √2 E13, √2 E12) so that the column norm is ‖E‖_F.
Eigen::MatrixXd element_strains(const Mesh& mesh, const Eigen::Matrix3Xd& x);

/// Σ V‖E‖³ / Σ V‖E‖² over the elements (0 at rest).
double strain_level(const Mesh& mesh, const Eigen::MatrixXd& strain);

/// A parameter set fitted to one measurement and the strain it was fitted at.
struct ParameterSet {
  std::string name;        // the measurement's
  Eigen::MatrixXd q;       // the elastic term's parameters × elements
  Eigen::MatrixXd strain;  // element_strains at the set's own equilibrium of it
};

enum class BlendMetric { kGlobal, kLocal };

struct BlendOptions {
  BlendMetric metric = BlendMetric::kGlobal;
  /// Local metric: the Gaussian's radius in space (m); ≤ 0: twice the mean
  /// element size (the cube root of the mean element volume).
  double radius = 0;
  int increments = 8;       // load increments
  int max_passes = 40;      // at the full load
  double tolerance = 1e-4;  // on the largest change of a weight between passes
};

class Blender {
 public:
  /// Throws kelvin::Error when there are no sets or their sizes differ from the mesh.
  Blender(const Mesh& mesh, std::vector<ParameterSet> sets, const BlendOptions& options = {});

  /// w: sets × elements, for the body strained as `strain` (6 × elements).
  Eigen::MatrixXd weights(const Eigen::MatrixXd& strain) const;
  /// The blended parameters (parameters × elements) for weights w.
  Eigen::MatrixXd parameters(const Eigen::MatrixXd& w) const;

  const std::vector<ParameterSet>& sets() const { return sets_; }
  const BlendOptions& options() const { return options_; }
  double width() const { return h_; }

 private:
  /// d_m(e)² for every set and element: sets × elements.
  Eigen::MatrixXd squared_distances(const Eigen::MatrixXd& strain) const;

  const Mesh& mesh_;
  std::vector<ParameterSet> sets_;
  BlendOptions options_;
  Eigen::VectorXd volume_;
  /// Local metric: per element, its neighbours j and their weights g V_j / Σ g V.
  std::vector<std::vector<std::pair<int, double>>> near_;
  std::vector<double> level_;  // the sets' strain levels (global metric)
  double h_ = 1;
};

struct BlendedEquilibrium {
  bool converged = false;
  std::string message;      // why not, when it did not
  Eigen::Matrix3Xd x;       // every node's equilibrium position
  Eigen::MatrixXd weights;  // sets × elements, at x
  Eigen::MatrixXd q;        // the blended parameters at x
  int passes = 0;           // at the full load
  double change = 0;        // the last pass's largest weight change
};

/// The equilibrium of `model` (its loads, clamps, one elastic term) with the blended
/// parameters, by incremental loading; leaves the model's elastic term at q.
BlendedEquilibrium blended_equilibrium(FemModel& model, const Blender& blender);

}  // namespace kelvin
