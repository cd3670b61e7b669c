#pragma once
/// \file
/// Derivatives of the momentum residual
///   R(t, x, v, v'; q) = M v' + M_fc a_c + r(x, v) − f_ext
/// with respect to per-element model quantities ("slots"): a material parameter of
/// one term, the density, a compliant clamp's compliance (one value, visited on
/// the elements its faces bound), or a body-force field's value at one knot. Both gradient methods
/// consume them: forward sensitivities scatter ∂R/∂q_e into a residual, the adjoint contracts it
/// with λ.
///
/// Everything is closed-form from the material's dP/dq, except where a term's
/// stress depends on the elastic rest tangent C₀ (stiffness-proportional Rayleigh
/// damping). Such stresses are linear in C₀ (a requirement of needs_rest_tangent),
/// so ∂P/∂q = P evaluated with C₀ replaced by ∂C₀/∂q; ∂C₀/∂q = ∂²P/∂F∂q at F = I is
/// the one quantity not supplied by the material interface and is taken from
/// Richardson-extrapolated central differences of the exact dP/dq (error ~h⁴ ≈ 1e-12).
#include <Eigen/Core>
#include <functional>
#include <vector>

#include "engine/fem_model.hpp"

namespace kelvin {

struct ParamSlot {
  int term = -1;   // material term index into FemModel::terms(); −1 = density
  int index = 0;   // parameter index within the term, or the body force's knot
  int clamp = -1;  // ≥ 0: the compliance of that (compliant) clamp
  int force = -1;  // ≥ 0: the body force's axis (at knot `index`)
  bool is_density() const { return term < 0 && clamp < 0 && force < 0; }
  bool is_clamp() const { return clamp >= 0; }
  bool is_material() const { return term >= 0; }
  bool is_force() const { return force >= 0; }
  bool operator==(const ParamSlot& o) const {
    return term == o.term && index == o.index && clamp == o.clamp && force == o.force;
  }
};

using Vec12 = Eigen::Matrix<double, 12, 1>;

class ParamDerivatives {
 public:
  ParamDerivatives(const FemModel& model, std::vector<ParamSlot> slots);

  const std::vector<ParamSlot>& slots() const { return slots_; }
  /// Recomputes what depends on the parameters (∂C₀/∂q); call after they change.
  void update();

  /// Calls visit(e, s, dR) for every element e and slot s, with dR = ∂R_e/∂q_{s,e}
  /// over the element's 12 node dofs (clamped ones included; callers skip them).
  /// x, v, a are full nodal fields at time t. False when a material rejects the state.
  /// `cached`, when it holds dP/dq (FemModel::element_tangents with
  /// param_derivatives) at this x and v, is used instead of evaluating the materials.
  /// With internal variables z (FemModel::num_internal; null: relaxed, as in static
  /// equilibrium, where such terms carry nothing), the stresses see them, and
  /// visit_internal(b, s, dF) gets the derivative of their rows z' − f = 0 in
  /// internal block b, dF = −∂f_b/∂q_{s}, for every slot of a term that has them.
  using Visitor = std::function<void(int e, int s, const Vec12& dR)>;
  using InternalVisitor = std::function<void(int b, int s, const Eigen::VectorXd& dF)>;
  bool for_each(double t, const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v,
                const Eigen::Matrix3Xd& a, const Visitor& visit,
                const ElementTangents* cached = nullptr, const double* z = nullptr,
                const InternalVisitor& visit_internal = {}) const;

 private:
  const FemModel& model_;
  std::vector<ParamSlot> slots_;
  void clamp_compliance_derivative(double t, const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v,
                                   int s, const Visitor& visit) const;
  std::vector<int> rest_tangent_users_;  // viscous terms whose stress uses C₀
  // ∂C₀/∂q per element for each slot that is an elastic parameter (empty otherwise)
  std::vector<std::vector<Mat9>> dC0_;
};

}  // namespace kelvin
