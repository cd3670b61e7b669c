#include <algorithm>
#include <cmath>

#include "adjoint/uncertainty.hpp"
#include "fit/fit_context.hpp"

namespace kelvin::fit_detail {
namespace {

/// The Gauss–Newton model of Φ about a point, from the JᵀJ of `u`: a root L of the
/// covariance C = σ̂² (JᵀJ)⁻¹ (any L with L Lᵀ = C serves; a direction the data barely
/// resolve, V09's λ at 660 Pa beside μ at 1.3e5 Pa, is scaled at the sensitivities'
/// accuracy rather than refused) and β = (N − n) / (2Φ), such that the Gauss–Newton
/// step is Δp_GN = −(1/κ)(JᵀJ)⁻¹ g = −β C g (κ = 2Φ / ‖r‖² relates Φ's time integral
/// to the sum over frames). False when JᵀJ is unavailable or singular.
bool gauss_newton_model(const ParameterUncertainty& u, double phi, int n, Eigen::MatrixXd& L,
                        double& beta) {
  if (u.root_inverse.rows() != n || !(phi > 0) || !(u.sigma > 0) || u.observations <= n)
    return false;
  L = u.sigma * u.root_inverse;
  beta = (u.observations - n) / (2 * phi);
  return L.allFinite();
}

}  // namespace

/// Gauss–Newton preconditioning for a restart of a stalled L-BFGS: in an
/// ill-conditioned valley (the occluded-bar fit: λ 1.9× off, its gradient 5× below
/// μ's, Φ's integration noise 1e-3 of the decrease a step could gain) the
/// restart's steepest-descent step only moves the stiff direction, and the line
/// search stalls again at every tolerance. With JᵀJ from the marker sensitivities
/// at the best point (the standard errors' computation, one sensitivity solve),
/// the fit continues in z, p = p_best + B z with B Bᵀ ∝ (JᵀJ)⁻¹, where the
/// Gauss–Newton Hessian is a multiple of the identity. B's scale makes L-BFGS's
/// first step (length ½ along −∇_z, see objective_scale) the Gauss–Newton step
/// −(1/κ)(JᵀJ)⁻¹∇Φ, κ = 2Φ / ‖r‖² relating Φ's time integral to the sum over
/// frames. False when JᵀJ is unavailable (too many parameters). A parameter that
/// moves no marker at the best point, or too little for the data to place it
/// (ParameterUncertainty::unresolved), keeps its value until the next restart.
bool precondition(Context& c, const Eigen::VectorXd& best, const Eigen::VectorXd& gradient) {
  UncertaintyAtPoint& cache = c.outcome.uncertainty;
  if (!cache.holds(best)) {
    cache.value = gauss_newton_uncertainty(c.problem, best, c.options.gradient.interrupt);
    cache.p = best;
  }
  Eigen::MatrixXd L;
  double beta = 0;
  if (!gauss_newton_model(cache.value, c.outcome.best.misfit, static_cast<int>(best.size()), L,
                          beta))
    return false;
  // B = s L makes L-BFGS's first step −½ B Lᵀg/|Lᵀg| the Gauss–Newton step for
  // s = 2β|Lᵀg|.
  const double s = 2 * beta * (L.transpose() * gradient).norm();
  if (!(s > 0) || !std::isfinite(s)) return false;
  c.basis = s * L;
  return true;
}

double predicted_gain(const Context& c, const Eigen::VectorXd& gradient) {
  const UncertaintyAtPoint& cache = c.outcome.uncertainty;
  const double phi = c.outcome.best.misfit;
  Eigen::MatrixXd L;
  double beta = 0;
  if (cache.p.size() != gradient.size() || !c.terms.empty() ||
      !gauss_newton_model(cache.value, phi, static_cast<int>(gradient.size()), L, beta))
    return NAN;
  // A parameter held by the scaling because it moved no marker where JᵀJ was computed
  // is outside the model: it predicts nothing about what moving it would gain. An
  // unresolved one (held too) is bounded by its slope across the range the data
  // leave it, kUnresolvedSpan spans: a steep slope there keeps the fit going.
  const Eigen::VectorXd rows = L.rowwise().squaredNorm();
  const std::vector<int>& unresolved = cache.value.unresolved;
  double held = 0;
  for (int j = 0; j < rows.size(); ++j) {
    if (rows[j] != 0) continue;
    if (std::find(unresolved.begin(), unresolved.end(), j) == unresolved.end()) return NAN;
    held += std::abs(gradient[j]) * kUnresolvedSpan * parameter_span(c.problem.map(), cache.p, j);
  }
  // The decrease to the Gauss–Newton model's minimum, ½ gᵀ(−Δp_GN) = ½ β |Lᵀg|², over Φ.
  const double gain = 0.5 * beta * (L.transpose() * gradient).squaredNorm() + held;
  return std::isfinite(gain) ? gain / phi : NAN;
}

}  // namespace kelvin::fit_detail
