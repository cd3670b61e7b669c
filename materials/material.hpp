#pragma once
/// \file
/// The constitutive interface. A material term evaluates, at one material point,
/// the first Piola–Kirchhoff stress P(F, Ḟ; q) and on request dP/dF, dP/dḞ, dP/dq
/// and the strain energy density Ψ(F; q). Elastic and viscous terms add up.
/// Nothing else in kelvin evaluates constitutive laws: the forward solver, the
/// Jacobian and every gradient come from here.
///
/// Tensor layout: 3×3 tensors are flattened column-major, index i + 3 j for A(i,j),
/// so dP/dF(a, b) = ∂vec(P)_a / ∂vec(F)_b.
#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

namespace kelvin {

using Mat3 = Eigen::Matrix3d;
using Mat9 = Eigen::Matrix<double, 9, 9>;
using Mat9X = Eigen::Matrix<double, 9, Eigen::Dynamic>;

struct ParamInfo {
  std::string name;  // key in the scenario file, e.g. "lambda"
  std::string unit;  // e.g. "Pa", "Pa s", "1"
  std::string description;
  double default_value = 0;
  double lower = -1e300, upper = 1e300;  // admissible closed range
  bool positive = false;                 // strictly positive: the fitter may optimise log q
};

/// What a caller wants from one evaluation (bit mask).
enum Request : unsigned {
  kStress = 1u,
  kTangent = 2u,          // dP/dF
  kRateTangent = 4u,      // dP/dḞ
  kParamDerivative = 8u,  // dP/dq
  kEnergy = 16u,
};

struct MaterialPoint {
  Mat3 F = Mat3::Identity();
  Mat3 Fdot = Mat3::Zero();
  const double* q = nullptr;      // this term's parameters, in params() order
  const double* state = nullptr;  // this element's fixed state (state_size() values), or null
  /// This element's internal variables z (internal_size() values), integrated with
  /// the motion; null for models without them.
  const double* internal = nullptr;
  int element = -1;  // for messages
  /// dP/dF at F = I of this element's elastic terms, supplied by the engine to
  /// models that ask for it (needs_rest_tangent), null otherwise.
  const Mat9* rest_tangent = nullptr;
};

struct MaterialResponse {
  Mat3 P = Mat3::Zero();
  Mat9 dPdF = Mat9::Zero();
  Mat9 dPdFdot = Mat9::Zero();
  Mat9X dPdq;  // 9 × params().size()
  Mat9X dPdz;  // 9 × internal_size(), with kTangent, for models with internal variables
  double energy = 0;
};

/// The evolution law ż = f(F, z; q) of a model's internal variables at one point,
/// and on request its derivatives (kTangent: ∂f/∂F, ∂f/∂z; kParamDerivative: ∂f/∂q).
struct InternalResponse {
  Eigen::VectorXd rate;  // f, internal_size()
  Eigen::MatrixXd dF;    // internal_size() × 9
  Eigen::MatrixXd dz;    // internal_size() × internal_size()
  Eigen::MatrixXd dq;    // internal_size() × params().size()
};

class Material {
 public:
  virtual ~Material() = default;
  virtual std::string name() const = 0;
  virtual const std::vector<ParamInfo>& params() const = 0;
  /// True when the stress depends on Ḟ (a damping term).
  virtual bool is_viscous() const = 0;
  /// True when P = ∂Ψ/∂F for the energy returned with kEnergy.
  virtual bool has_energy() const { return false; }
  /// Per-element data the model needs that is not fitted (e.g. a fibre direction):
  /// its size, and the value used where a scenario gives none.
  virtual int state_size() const { return 0; }
  virtual std::vector<double> default_state() const { return {}; }
  /// Internal variables: per element, integrated with the motion by IDAS (a relaxing
  /// branch's viscous strain). The stress depends on them (MaterialPoint::internal)
  /// and they follow ż = f(F, z; q) (evolve). Models without them return 0.
  virtual int internal_size() const { return 0; }
  /// The z at which they stay put while F is held (f(F, z) = 0): where a body at
  /// rest or in static equilibrium starts. Such a term carries no stress there.
  virtual void relaxed_internal(const Mat3& /*F*/, const double* /*q*/, double* /*z*/) const {}
  /// Fills `out` with f and the requested derivatives (sized by the model).
  virtual void evolve(const MaterialPoint& /*in*/, unsigned /*request*/,
                      InternalResponse& /*out*/) const {}
  /// Stiffness-proportional damping needs the elastic rest tangent C0 of the element
  /// (MaterialPoint::rest_tangent).
  virtual bool needs_rest_tangent() const { return false; }
  /// Index of a parameter α such that the term also adds the mass-proportional
  /// damping force α M v (which no stress can express), or −1.
  virtual int mass_damping_param() const { return -1; }
  /// Fills the requested fields of `out` (others are left untouched, except that
  /// dPdq is resized). Returns false when the state is inadmissible (e.g. det F ≤ 0);
  /// callers turn that into a message naming the element.
  virtual bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const = 0;
};

/// Built-in models by scenario name ("neo-hookean", "newtonian", "power-law", ...).
/// Returns nullptr for an unknown name.
std::unique_ptr<Material> create_builtin_material(const std::string& name);
/// A built-in model (plugin_path empty) or a model from a plugin library; throws
/// kelvin::Error when the model or the plugin cannot be had.
std::unique_ptr<Material> create_material(const std::string& name, const std::string& plugin_path);
/// Names of all built-in models, sorted.
std::vector<std::string> builtin_material_names();

}  // namespace kelvin
