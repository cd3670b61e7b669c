// Forward sensitivities with IDAS FSA (staggered corrector, analytic residual):
//   s_x' − s_v = 0,   M s_v' + K s_x + D s_v + K_xz s_z + ∂R/∂p_j = 0,
//   s_z' − f_x s_x − f_z s_z − ∂f/∂p_j = 0 (internal variables z, when there are some),
// with dΦ/dp_j = ∫ ∂g/∂x · s_x,j dt as a quadrature sensitivity. One linear system
// per parameter per step: the cost grows with the number of parameters, which is
// what the adjoint avoids.
#include <cstring>
#include <functional>

#include "adjoint/experiment_run.hpp"
#include "base/error.hpp"

namespace kelvin {
namespace {

/// K, D and ∂R/∂p at the last (t, y, y') they were computed for: IDAS evaluates
/// the sensitivity residual several times per step at the same state.
struct StateCache {
  double t = NAN;
  Eigen::VectorXd y, yp;
  bool matches(double tt, const double* yy, const double* yyp, int size) const {
    return tt == t && y.size() == size && std::memcmp(y.data(), yy, sizeof(double) * size) == 0 &&
           std::memcmp(yp.data(), yyp, sizeof(double) * size) == 0;
  }
  void store(double tt, const double* yy, const double* yyp, int size) {
    t = tt;
    y = Eigen::Map<const Eigen::VectorXd>(yy, size);
    yp = Eigen::Map<const Eigen::VectorXd>(yyp, size);
  }
};

/// y += A x for values A in the FEM pattern.
void pattern_multiply(const SparsePattern& P, const std::vector<double>& A, const double* x,
                      double* y) {
  for (int c = 0; c < P.n; ++c)
    for (int k = P.colptr[c]; k < P.colptr[c + 1]; ++k) y[P.rowind[k]] += A[k] * x[c];
}

}  // namespace

Eigen::MatrixXd ExperimentRun::add_sensitivities(IdasIntegrator& integ, bool error_control) {
  const std::vector<int> entries = sensitivity_entries();
  const int ns = static_cast<int>(entries.size());
  const SparsePattern& P = model.pattern();
  const int size = state_size(), m = size - 2 * n;
  if (ns == 0) return Eigen::MatrixXd(size, 0);

  // Initial sensitivities: x₀_p from the static state (zero from rest), v₀_p = 0,
  // z₀_p following x₀_p (z₀ is relaxed at x₀), and consistent derivatives
  // s_v' = −M⁻¹(K s_x + D s_v + K_xz s_z + ∂R/∂p), s_z' = f_x s_x + f_z s_z + ∂f/∂p at t₀.
  Eigen::MatrixXd yS0 = Eigen::MatrixXd::Zero(size, ns), ypS0 = Eigen::MatrixXd::Zero(size, ns);
  Eigen::MatrixXd B;
  if (static_initial()) {
    factor_static_stiffness();
    if (!param_vectors(B)) throw Error("an element is inadmissible at the static state");
    for (int j = 0; j < ns; ++j) yS0.col(j).head(n) = -K0->solve(B.col(entries[j]).head(n));
    if (m > 0)
      for (int j = 0; j < ns; ++j)
        model.relaxed_internal_change(x, yS0.col(j).data(), yS0.col(j).data() + 2 * n);
  }
  {
    Eigen::VectorXd y(size), yp(size);
    y << x0, v0, z0;
    if (!dae.consistent_derivative(t0, y.data(), yp.data()) ||
        !dae.stiffness_and_damping(t0, y.data()))
      throw Error("the initial state is inadmissible");
    expand(t0, y.data(), yp.data());
    if (!param_vectors(B)) throw Error("an element is inadmissible at the initial state");
    const AssemblyOutput& out = dae.last_assembly();
    for (int j = 0; j < ns; ++j) {
      Eigen::VectorXd r = Eigen::VectorXd::Zero(size);  // ∂F/∂y s + ∂F/∂p without the s' terms
      pattern_multiply(P, out.K, yS0.col(j).data(), r.data() + n);
      dae.add_internal_product(yS0.col(j).data(), r.data());
      r.tail(n + m) += B.col(entries[j]);
      Eigen::VectorXd rhs = -r.segment(n, n);
      dae.mass_solve(rhs.data(), ypS0.col(j).data() + n);
      ypS0.col(j).tail(m) = -r.tail(m);
    }
  }

  // Sensitivity error weights scale with the parameter: dy/d(ln q) has the units
  // of y; dy/dq is measured per typical q, at least the block's scale, so that an
  // entry at 0 keeps finite weights and its Newton test means something.
  Eigen::VectorXd pbar(ns);
  for (int j = 0; j < ns; ++j) {
    const ParameterBlock& b = map.block_of_entry(entries[j]);
    pbar[j] = b.log || b.is_multiplier() ? 1.0 : std::max(std::abs(p[entries[j]]), b.scale);
  }

  auto cache = std::make_shared<StateCache>();
  auto params = std::make_shared<Eigen::MatrixXd>();
  integ.add_sensitivities(
      [this, cache, params, entries](double t, const double* y, const double* yp, int count,
                                     const double* const* yS, const double* const* ypS,
                                     double* const* resS) {
        const int size = state_size();
        if (!cache->matches(t, y, yp, size)) {
          if (!dae.stiffness_and_damping(t, y)) return false;
          expand(t, y, yp);
          if (!param_vectors(*params)) return false;
          cache->store(t, y, yp, size);
        }
        const AssemblyOutput& out = dae.last_assembly();
        const SparsePattern& P = model.pattern();
        for (int j = 0; j < count; ++j) {
          double* r = resS[j];
          for (int i = 0; i < n; ++i) r[i] = ypS[j][i] - yS[j][n + i];
          Eigen::Map<Eigen::VectorXd>(r + n, size - n) = params->col(entries[j]);
          for (int i = 2 * n; i < size; ++i) r[i] += ypS[j][i];
          model.mass_multiply(ypS[j] + n, r + n);
          pattern_multiply(P, out.K, yS[j], r + n);
          pattern_multiply(P, out.D, yS[j] + n, r + n);
          dae.add_internal_product(yS[j], r);
        }
        return true;
      },
      yS0, ypS0, pbar, error_control);
  return yS0;
}

void evaluate_forward_sensitivities(ExperimentRun& run, ExperimentResult& result) {
  const int n = run.n;
  auto integ = run.start(run.t0, run.x0, run.v0, run.z0);
  // A gradient for the line search: its accuracy is worth the extra steps.
  const std::vector<int> entries = run.sensitivity_entries();
  const Eigen::MatrixXd yS0 = run.add_sensitivities(*integ, true);
  if (!entries.empty() && run.objective.num_markers() + run.observation_count > 0)
    integ->add_quadrature_sensitivities([&run, n](double t, const double* y, const double*, int ns,
                                                  const double* const* yS, double* const* qS) {
      Eigen::Matrix3Xd x, v;
      run.model.expand(t, y, nullptr, x, v);
      Eigen::VectorXd grad = Eigen::VectorXd::Zero(n);
      run.objective.add_gradient(t, run.model, x, grad.data());
      const int nq = run.objective.num_markers() + run.observation_count;
      for (int j = 0; j < ns; ++j) {
        // Only the sum over markers is needed: it is carried in component 0.
        std::fill(qS[j], qS[j] + nq, 0.0);
        qS[j][0] = grad.dot(Eigen::Map<const Eigen::VectorXd>(yS[j], n));
      }
      return true;
    });

  result.gradient = Eigen::VectorXd::Zero(run.map.size());
  // A shape target adds ∂Φ_k/∂x · s_x at its time; IDAS stops there (fixed_times).
  const auto add_target_terms = [&](double t, const Eigen::VectorXd& x_free,
                                    const std::function<Eigen::MatrixXd()>& sensitivities) {
    run.add_targets(t, x_free, result);
    Eigen::VectorXd g = Eigen::VectorXd::Zero(n);
    run.add_target_gradient(t, x_free, g.data());
    if (entries.empty() || g.isZero(0)) return;
    const Eigen::MatrixXd s = sensitivities();
    for (size_t j = 0; j < entries.size(); ++j)
      result.gradient[entries[j]] += g.dot(s.col(static_cast<long>(j)).head(n));
  };
  add_target_terms(run.t0, run.x0, [&] { return yS0; });
  const std::vector<double> T = run.fixed_times();
  for (size_t k = 1; k < T.size(); ++k) {
    if (!run.advance(*integ, T[k], result)) {
      result.forward_stats = integ->stats();
      return;  // the quadrature is unreadable after a failure (integrate_segments)
    }
    add_target_terms(T[k], integ->positions(), [&] { return integ->state_sensitivities(); });
  }
  result.forward_stats = integ->stats();
  run.add_quadratures(*integ, result);
  // Component 0 carries the sum over markers (above); observation entries have no
  // state sensitivity: their gradient is the objective's own.
  if (!entries.empty() && run.objective.num_markers() + run.observation_count > 0) {
    const Eigen::MatrixXd qS = integ->quadrature_sensitivities();
    for (size_t j = 0; j < entries.size(); ++j) result.gradient[entries[j]] += qS(0, j);
  }
  if (run.observation_count > 0)
    run.map.add_observation_gradient(result.dphi_dtheta, result.gradient);
  result.ok = true;
}

}  // namespace kelvin
