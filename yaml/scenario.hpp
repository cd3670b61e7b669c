#pragma once
// A scenario file, parsed and validated. Everything here is resolved: the mesh is
// loaded, clamp selections are node lists, CSV files are read, markers embedded.
// The engine builds a model from this without knowing about YAML.
#include <Eigen/Core>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "engine/csv.hpp"
#include "engine/markers.hpp"
#include "engine/mesh.hpp"
#include "engine/rigid_motion.hpp"
#include "engine/selection.hpp"
#include "materials/material.hpp"

namespace kelvin {

/// The most tetrahedra a scenario may generate or refine to: a direct solve beyond
/// this (over a million unknowns) would not fit a workstation's memory.
constexpr double kMaxMeshTets = 2e6;

/// One constitutive term (`elastic:` or `viscous:`): model name and parameter values.
struct MaterialTermSpec {
  std::string model;                     // e.g. "neo-hookean", "newtonian", "power-law"
  std::map<std::string, double> params;  // every parameter of the model, defaults filled in
  std::string plugin;                    // path of a plugin library ("" for built-ins)
  std::vector<double> state;             // per-element fixed state; empty = model's default
};

/// One column of `material.fields`: a quantity given element by element, which
/// replaces the scalar of the same name everywhere.
struct MaterialField {
  std::string target;      // a MaterialQuantity's name ("density", "elastic.mu", ...)
  int term = -1;           // −1 density, else the FemModel::terms() index
  int index = 0;           // parameter index in the term's model params()
  Eigen::VectorXd values;  // per element, model units
};

/// The material: elastic terms (at least one) and viscous terms (any number) whose
/// stresses add up. A model is built with the elastic terms first, then the viscous
/// ones (FemModel::terms() order, see term_index).
struct MaterialSpec {
  double density = 0;  // kg/m³
  std::vector<MaterialTermSpec> elastic, viscous;
  std::string fields_path;            // resolved `material.fields` ("" if none)
  std::vector<MaterialField> fields;  // in the file's column order

  int num_terms() const { return static_cast<int>(elastic.size() + viscous.size()); }
  /// FemModel::terms() index of term k of the elastic or the viscous list.
  int term_index(bool is_viscous, int k) const {
    return is_viscous ? static_cast<int>(elastic.size()) + k : k;
  }
  /// The term with FemModel::terms() index `term`.
  const MaterialTermSpec& term(int term) const;
  MaterialTermSpec& term(int term);
};

/// A quantity of the material that fields and fits can name: "density", or a
/// parameter <p> of a term as "elastic.<p>" / "viscous.<p>" (when only one term of
/// that kind has <p>) or "elastic[k].<p>" / "viscous[k].<p>" (term k of the list).
struct MaterialQuantity {
  std::string name;     // the short form when unambiguous, else the indexed one
  std::string indexed;  // "elastic[k].<p>"; "density" for the density
  int term = -1;        // FemModel::terms() index; −1 density
  int index = 0;        // parameter index in the term's model
  std::string model;    // the term's model name ("" for the density)
  ParamInfo info;       // unit, admissible range, positivity
  double value = 0;     // the scenario's value
};
/// Every quantity of the material, density first, terms in FemModel order.
std::vector<MaterialQuantity> material_quantities(const MaterialSpec& material);
/// The quantity called `name` (either form), or null.
const MaterialQuantity* find_quantity(const std::vector<MaterialQuantity>& quantities,
                                      const std::string& name);

struct ClampSpec {
  std::string name;
  NodeSelection selection;
  std::vector<int> nodes;               // resolved, non-empty
  std::shared_ptr<RigidMotion> motion;  // FixedMotion when none is given
  double compliance = 0;                // m³/N; > 0: held by springs (ClampBinding)
  double damping_time = 0;              // s, the pads' retardation time, with compliance only
  bool ramped = false;                  // a pressed probe (PressSpec), never from `clamps:`
};

/// `probing.measurements[].press:` entry: a probe pressed to a depth. Its nodes are
/// held at rest + `displacement` (a ramped clamp: static load steps bring it in), and
/// the force it exerts on the body may have been measured.
struct PressSpec {
  ClampSpec clamp;  // ramped; its motion the translation `displacement`
  Eigen::Vector3d displacement = Eigen::Vector3d::Zero();
  /// N, the measured force of the probe on the body; NaN when not measured.
  Eigen::Vector3d reaction = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
};

/// `loads:` entry: a constant force and/or an attached mass carried by the
/// selected free nodes in equal shares (engine/fem_model.hpp, NodeLoad).
struct LoadSpec {
  std::string name;
  NodeSelection selection;
  std::vector<int> nodes;                           // resolved; at least one is free of the clamps
  Eigen::Vector3d force = Eigen::Vector3d::Zero();  // N, total
  double mass = 0;                                  // kg, total
};

struct MarkersSpec {
  std::vector<MarkerEmbedding> embedded;  // empty when the scenario has no markers
  std::string observed_path;              // optional captured tracks ("" if none)
  MarkerTracks observed;                  // the tracks read from observed_path
};

struct TimeSpec {
  double end = 1.0;          // s
  double output_rate = 100;  // frames per second for marker CSV
  double vtu_rate = 0;       // frames per second for VTU output; 0 = none
};
/// Output frames are held in memory until written: at most this many marker frames
/// and VTU frames per run (10⁷ frames of 100 markers are 24 GB of CSV already).
constexpr double kMaxOutputFrames = 1e7, kMaxVtuFrames = 1e5;
/// Why a time span cannot be run ("" when it can): too many output frames.
std::string time_span_problem(const TimeSpec& time);

struct SolverSpec {
  /// At 1e-4 with the automatic order, the markers of the diagnosis bar (V01, BDF2)
  /// are within 0.025 mm of a tight reference and those of the bench bar (BDF5)
  /// within 0.0004 mm (bench_work_precision).
  double rtol = 1e-4;
  double atol = 1e-9;  // positions (m); velocities use atol × velocity_atol_scale
  double velocity_atol_scale = 100;
  int max_order = 0;         // 1 … 5, or 0 = auto: chosen per run (engine/order_policy.hpp)
  long max_steps = 1000000;  // over the whole run
  double max_step = 0;       // 0 = unlimited
  double initial_step = 0;   // 0 = IDAS default
  bool lumped_mass = true;
};

/// One fitted quantity of the `fit:` section. Values are in model units (Pa, kg/m³…);
/// the log transform, when on, is applied by the parameter map.
/// Observation targets (adjoint/parameter_map.hpp, ObservationBlock): the marker
/// clock's offset, a marker's rest-position offset (`markers.<name>.offset`) and the
/// capture frame's rigid registration.
inline const char* kClockOffset = "markers.clock_offset";
inline const char* kRegistration = "markers.registration";
/// The marker a `markers.<name>.offset` target names, or "" when it is not one.
inline std::string marker_of_offset_target(const std::string& target) {
  const std::string prefix = "markers.", suffix = ".offset";
  if (target.size() <= prefix.size() + suffix.size() || target.rfind(prefix, 0) != 0 ||
      target.compare(target.size() - suffix.size(), suffix.size(), suffix) != 0)
    return "";
  return target.substr(prefix.size(), target.size() - prefix.size() - suffix.size());
}

/// The clamp a `clamps.<name>.compliance` target names, or "" when it is not one.
inline std::string clamp_of_compliance_target(const std::string& target) {
  const std::string prefix = "clamps.", suffix = ".compliance";
  if (target.size() <= prefix.size() + suffix.size() || target.rfind(prefix, 0) != 0 ||
      target.compare(target.size() - suffix.size(), suffix.size(), suffix) != 0)
    return "";
  return target.substr(prefix.size(), target.size() - prefix.size() - suffix.size());
}

/// A body-force field per unit mass along one axis (`body_force.x|y|z`, m/s²): the
/// target's scope sets its space basis, `knots` its hats in time (engine/body_force.hpp).
/// The axis (0, 1, 2) of such a target, or −1.
inline int body_force_axis(const std::string& target) {
  for (int i = 0; i < 3; ++i)
    if (target == std::string("body_force.") + "xyz"[i]) return i;
  return -1;
}

/// The target of a multiplier of every elastic modulus (each parameter in Pa of every
/// elastic term): the stiffness field scaled by one factor, 1 = the scenario's.
inline const char* kElasticModuli = "elastic.moduli";

struct FitParameterSpec {
  std::string target;  // a MaterialQuantity's name, or kElasticModuli
  enum class Scope { Global, PerRegion, PerElement, Boxes, Legendre } scope = Scope::Global;
  /// Scope::Boxes: an element whose centroid lies in box k gets parameter k (first
  /// match); elements in no box share one more parameter.
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> boxes;  // (min, max)
  /// Scope::Legendre: the quantity is the scenario's times exp(Σₖ cₖ Pₖ(s)), Pₖ the
  /// Legendre polynomials of degree `from` ≤ k ≤ `degree` in the element centroid's
  /// coordinate along `axis` mapped onto [−1, 1] over the mesh; p holds the cₖ (0 = the
  /// scenario). `from` = 1 leaves the mean to a global parameter fitted beside it.
  int legendre_axis = 2, legendre_degree = 0, legendre_from = 0;
  std::optional<double> initial;  // default: the scenario's value
  double lower = 0, upper = 0;    // admissible range (defaults from the model's ParamInfo)
  bool log = false;               // optimise ln q (default: true for strictly positive q)
  /// A linear parameter's typical size: the optimiser moves in units of it. 0: |start|,
  /// or where that is 0 (a nested extension) the size of the scenario's quantities in
  /// the same unit (see ParameterMap::units).
  double scale = 0;
  /// Body-force targets: hats in time inside [0, time.end] (one block of the scope's
  /// entries per knot); every body-force target of a fit has the same knots.
  int knots = 0;
  /// A Gaussian prior at 0 on a linear parameter: Φ gains penalty · Σⱼ (pⱼ/scale)²,
  /// in Φ's unit (m² s). 0: none.
  double penalty = 0;
  int line = 0;  // 1-based line in the scenario file, for messages
};

/// A log-transformed fit parameter bounded only below by 0 (what the loader gives
/// a strictly positive parameter by default), for fits set up in code.
inline FitParameterSpec positive_fit_parameter(
    const std::string& target, FitParameterSpec::Scope scope = FitParameterSpec::Scope::Global) {
  FitParameterSpec s;
  s.target = target;
  s.scope = scope;
  s.lower = 0;
  s.upper = 1e300;
  s.log = true;
  return s;
}

/// A parameter fitted as it is (no log) within [lower, upper], for fits set up in
/// code: nested extensions, whose nominal value is 0.
inline FitParameterSpec linear_fit_parameter(const std::string& target, double lower,
                                             double upper) {
  FitParameterSpec s;
  s.target = target;
  s.lower = lower;
  s.upper = upper;
  return s;
}

/// A shape the body should have at one time (Real2Sim §5, Fig. 10: a face made flat
/// at t = 0.2 s): Φ gains w/2 Σ (x_{n,a}(t) − x̄_{n,a})² over the selected nodes n and
/// the axes a that count.
struct ShapeTargetSpec {
  std::string name;
  double time = 0;  // s, within [0, time.end]
  NodeSelection selection;
  std::vector<int> nodes;  // the selection resolved, or the nodes of `positions_path`
  /// Every axis counts, x̄ given per node (positions, a file's rows) or x̄ = X + offset
  /// (rest positions moved); or only plane_axis counts, x̄ = plane_at (a flat face).
  std::string positions_path;
  Eigen::Matrix3Xd positions;  // per entry of nodes when positions_path is set
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();
  int plane_axis = -1;  // −1: offset target
  double plane_at = 0;  // m
  double weight = 1;    // s: one coordinate weighs like a marker coordinate seen this long
  int line = 0;         // 1-based line in the scenario file, for messages
};

/// The objective: the marker misfit Φ = ½ ∫ Σᵢ wᵢ ‖x*ᵢ − x̄ᵢ‖² dt over a time window,
/// plus the shape targets of this scenario's motion.
struct ObjectiveSpec {
  std::map<std::string, double> weights;  // marker name → wᵢ (1 when absent; 0 drops it)
  double window_begin = 0;                // s
  double window_end = -1;                 // s; < 0 = the end of the run
  std::vector<ShapeTargetSpec> targets;
};

struct FitSpec {
  bool present = false;
  std::vector<FitParameterSpec> parameters;
  ObjectiveSpec objective;
  std::string gradient = "adjoint";  // adjoint | forward | none
  std::string algorithm = "lbfgs";   // lbfgs | mma | slsqp | bobyqa
  int max_evaluations = 200;
  double ftol_rel = 1e-10, xtol_rel = 1e-8;
  double max_seconds = 0;                // 0 = no limit
  double smoothness = 0;                 // γ of the per-element smoothness term
  double spline_slope_penalty = 0;       // w of the falling-spline penalty (m² s / Pa²)
  std::vector<double> lcurve;            // γ values of an L-curve sweep (empty = none)
  std::vector<std::string> experiments;  // further scenario files fitted jointly
  int checkpoint_steps = 0;              // most steps one adjoint segment stores; 0 = default
  double segment = 0;                    // s per adjoint segment; 0 = automatic
  double start_rtol = 0;                 // rtol of the fit's first stage; 0 = automatic
  /// A global start before the local fit: "stiffness" (a scan of a common scale of
  /// the fitted moduli), "none", or empty when not given (kelvin fit: none;
  /// kelvin diagnose's nominal fit: stiffness).
  std::string start_scan;
};

struct Scenario {
  std::string name;
  std::string path;  // the scenario file, for messages
  Mesh mesh;
  MaterialSpec material;
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();
  bool static_initial = false;  // initial: static (equilibrium at t=0) or rest
  std::vector<ClampSpec> clamps;
  std::vector<LoadSpec> loads;
  MarkersSpec markers;
  TimeSpec time;
  SolverSpec solver;
  FitSpec fit;
  /// What the loader adjusted that the user should hear of once (e.g. reordered
  /// tetrahedra); the commands print them as notes.
  std::vector<std::string> notes;
};

/// Solver tolerances of a fit's first stage relative to the scenario's (≥ 1):
/// fit.start_rtol / solver.rtol, by default min(1e-3, 100 × rtol) / rtol (1 when
/// rtol ≥ 1e-3). At 1e-3 the bench bar's adjoint gradient is within 5 % of a tight
/// one's from the 2×-off start; at 1e-2 it is off by 2× and the stage wastes steps.
double fit_start_tolerance_scale(const Scenario& s);

/// Parses and validates a scenario. Throws kelvin::Error whose message begins
/// "file:line:col: key.path: " and says why the value is refused.
Scenario load_scenario(const std::string& path);

}  // namespace kelvin
