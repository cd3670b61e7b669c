#include "probing/displacement_inverse.hpp"

#include <fmt/format.h>

#include <Eigen/SparseCholesky>
#include <cmath>
#include <exception>
#include <nlopt.hpp>

#include "base/error.hpp"
#include "engine/static_solver.hpp"

namespace kelvin {
namespace {

/// L-BFGS's first step in log θ: a factor 1.65 (kelvin's fit loop takes the same).
constexpr double kFirstStep = 0.5;

struct Problem {
  explicit Problem(std::vector<ObservedProbe>& m) : ms(m) {}
  std::vector<ObservedProbe>& ms;
  int term = 0, nq = 0, groups = 0;
  std::vector<int> group;
  Eigen::SparseMatrix<double> L;  // smoothness over log θ
  double reg = 0;                 // γ² S / n_L
  double data_size = 1;           // S
  std::vector<Eigen::VectorXd> x_free;
  int evaluations = 0;
  double best = INFINITY, best_data = INFINITY, best_reaction = 0;
  double reaction = 0;  // ½ c Σ ‖R − R̄‖² of the last evaluation
  Eigen::VectorXd best_z;
  std::string failure;       // of the last failed trial
  std::exception_ptr error;  // thrown by an evaluation: ends the fit, rethrown
  int failed = 0;
  double scale = 0;  // Φ's factor: L-BFGS's first step is kFirstStep long

  /// Φ / S and its gradient in z = log θ; false when a static solve fails.
  bool evaluate(const Eigen::VectorXd& z, double& phi, double& data, Eigen::VectorXd* grad) {
    const Mesh& mesh = ms[0].model->mesh();
    const int columns = groups * nq;
    Eigen::VectorXd dphi = Eigen::VectorXd::Zero(columns);
    data = 0;
    reaction = 0;
    for (size_t m = 0; m < ms.size(); ++m) {
      FemModel& model = *ms[m].model;
      Eigen::MatrixXd& q = model.terms()[term].q;
      for (int e = 0; e < mesh.num_tets(); ++e)
        q.col(e) = z.segment(group[e] * nq, nq).array().exp();
      StaticResult s = solve_static(model, 0, x_free[m]);
      if (!s.converged) {
        x_free[m] = rigid_initial_guess(model, 0);
        s = solve_static(model, 0, x_free[m]);
      }
      if (!s.converged) {
        failure = fmt::format("measurement {}: no static equilibrium ({})", m, s.message);
        return false;
      }
      Eigen::Matrix3Xd x, v;
      const Eigen::VectorXd zero = Eigen::VectorXd::Zero(x_free[m].size());
      model.expand(0, x_free[m].data(), zero.data(), x, v);
      const Eigen::Matrix3Xd at = marker_positions(mesh, ms[m].markers, x);
      Eigen::Matrix3Xd pull = Eigen::Matrix3Xd::Zero(3, mesh.num_nodes());
      for (int j = 0; j < at.cols(); ++j) {
        if (!ms[m].observed.col(j).allFinite()) continue;
        const Eigen::Vector3d r = at.col(j) - ms[m].observed.col(j);
        data += 0.5 * r.squaredNorm();
        const MarkerEmbedding& mk = ms[m].markers[j];
        for (int a = 0; a < 4; ++a) pull.col(mesh.tets(a, mk.tet)) += mk.weights[a] * r;
      }
      // Measured reactions: their misfit, and (∂R/∂x)ᵀ c ΔR into the adjoint's load.
      std::vector<std::pair<ClampReaction, Eigen::Vector3d>> presses;
      Eigen::VectorXd rhs = Eigen::VectorXd::Zero(model.num_dofs());
      for (const auto& [clamp, seen] : ms[m].reactions) {
        ClampReaction press(model, clamp);
        Eigen::Vector3d R;
        if (!press.force(x, R)) {
          failure = fmt::format("measurement {}: element {} inadmissible", m, press.failed_element);
          return false;
        }
        const Eigen::Vector3d dR = ms[m].reaction_weight * (R - seen);
        reaction += 0.5 * dR.dot(R - seen);
        if (grad && !press.add_position_adjoint(x, dR, rhs)) {
          failure = fmt::format("measurement {}: element {} inadmissible", m, press.failed_element);
          return false;
        }
        presses.emplace_back(std::move(press), dR);
      }
      if (!grad) continue;
      AssemblyRequest req;
      req.force = false, req.stiffness = true;
      AssemblyOutput out;
      v.setZero();
      if (!model.assemble(x, v, req, out)) {
        failure = fmt::format("measurement {}: element {} inadmissible", m, out.failed_element);
        return false;
      }
      Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Lower> K(
          to_sparse_matrix(model.pattern(), out.K));
      Eigen::VectorXd marker_load(model.num_dofs());
      model.restrict(pull, marker_load.data());
      rhs += marker_load;
      const Eigen::VectorXd lambda = K.solve(rhs);
      if (K.info() != Eigen::Success || !lambda.allFinite()) {
        failure = fmt::format("measurement {}: the stiffness at equilibrium is singular", m);
        return false;
      }
      dphi -=
          force_parameter_jacobian(model, term, x, group, columns, 0, false).transpose() * lambda;
      for (const auto& [press, dR] : presses)
        dphi += reaction_parameter_jacobian(model, term, press, x, group, columns).transpose() * dR;
    }
    const Eigen::VectorXd Lz = L.rows() ? Eigen::VectorXd(L * z) : Eigen::VectorXd();
    phi = (data + reaction + 0.5 * reg * Lz.squaredNorm()) / data_size;
    if (grad) {
      *grad = z.array().exp().matrix().cwiseProduct(dphi);
      if (L.rows()) *grad += reg * (L.transpose() * Lz);
      *grad /= data_size;
    }
    return true;
  }
};

/// What a failed static solve returns: far above any Φ, so that L-BFGS's line search
/// backs off from the trial (as kelvin's fit loop does with its failed trials).
constexpr double kFailedTrial = 1e30;

double objective(unsigned n, const double* zp, double* grad, void* data) {
  Problem& p = *static_cast<Problem*>(data);
  const Eigen::VectorXd z = Eigen::Map<const Eigen::VectorXd>(zp, n);
  double phi = 0, fit = 0;
  Eigen::VectorXd g;
  ++p.evaluations;
  bool ok = false;
  try {
    ok = p.evaluate(z, phi, fit, grad ? &g : nullptr);
  } catch (...) {  // NLopt would report it as a generic failure: keep it to rethrow
    p.error = std::current_exception();
    throw nlopt::forced_stop();
  }
  if (!ok) {
    ++p.failed;
    if (grad) std::fill(grad, grad + n, 0.0);
    return kFailedTrial;
  }
  if (p.scale == 0) p.scale = g.norm() > 0 ? kFirstStep / g.norm() : 1 / phi;
  if (grad) Eigen::Map<Eigen::VectorXd>(grad, n) = p.scale * g;
  if (phi < p.best) p.best = phi, p.best_data = fit, p.best_reaction = p.reaction, p.best_z = z;
  return p.scale * phi;
}

}  // namespace

DisplacementInverseResult displacement_based_inverse(std::vector<ObservedProbe>& ms,
                                                     const DisplacementInverseOptions& o) {
  if (ms.empty()) throw Error("displacement-based inverse: no measurement");
  const FemModel& first = *ms[0].model;
  const Mesh& mesh = first.mesh();
  Problem p(ms);
  p.term = elastic_term(first);
  const Material& law = *first.terms()[p.term].model;
  p.nq = static_cast<int>(law.params().size());
  for (const auto& info : law.params())
    if (!info.positive)
      throw Error(fmt::format(
          "displacement-based inverse: parameter '{}' of '{}' is not declared positive; the fit "
          "works in log space",
          info.name, law.name()));
  std::tie(p.group, p.groups) = element_groups(mesh, o.grouping);

  p.data_size = 0;
  int observed = 0;
  for (size_t m = 0; m < ms.size(); ++m) {
    const FemModel& model = *ms[m].model;
    if (&model.mesh() != &mesh || elastic_term(model) != p.term ||
        model.terms()[p.term].model->name() != law.name())
      throw Error(
          fmt::format("displacement-based inverse: measurement {} is of another mesh or material "
                      "than the first",
                      m));
    if (ms[m].observed.cols() != static_cast<int>(ms[m].markers.size()))
      throw Error(fmt::format(
          "displacement-based inverse: measurement {} has {} observed positions for {} markers", m,
          ms[m].observed.cols(), ms[m].markers.size()));
    const Eigen::Matrix3Xd rest = marker_positions(mesh, ms[m].markers, mesh.nodes);
    for (int j = 0; j < rest.cols(); ++j)
      if (ms[m].observed.col(j).allFinite())
        ++observed, p.data_size += (ms[m].observed.col(j) - rest.col(j)).squaredNorm();
    p.x_free.push_back(rigid_initial_guess(model, 0));
  }
  if (observed == 0 || !(p.data_size > 0))
    throw Error("displacement-based inverse: no marker is observed away from its rest position");

  if (o.grouping == ElementGrouping::kElement && o.gamma_space > 0) {
    const auto pairs = face_neighbours(mesh);
    std::vector<Eigen::Triplet<double>> t;
    int row = 0;
    for (const auto& [e, f] : pairs)
      for (int k = 0; k < p.nq; ++k, ++row) {
        t.emplace_back(row, e * p.nq + k, 1.0);
        t.emplace_back(row, f * p.nq + k, -1.0);
      }
    p.L.resize(row, p.groups * p.nq);
    p.L.setFromTriplets(t.begin(), t.end());
    p.reg = o.gamma_space * o.gamma_space * p.data_size / std::max(row, 1);
  }

  // Start: each group's mean of the first model's values, in log space.
  Eigen::VectorXd z = Eigen::VectorXd::Zero(p.groups * p.nq);
  Eigen::VectorXi count = Eigen::VectorXi::Zero(p.groups);
  for (int e = 0; e < mesh.num_tets(); ++e) {
    z.segment(p.group[e] * p.nq, p.nq) += first.terms()[p.term].q.col(e);
    ++count[p.group[e]];
  }
  for (int g = 0; g < p.groups; ++g)
    z.segment(g * p.nq, p.nq) = (z.segment(g * p.nq, p.nq) / std::max(count[g], 1)).array().log();
  if (!z.allFinite()) throw Error("displacement-based inverse: the start values must be positive");
  {
    double phi = 0, data = 0;
    if (!p.evaluate(z, phi, data, nullptr))
      throw Error("displacement-based inverse: at the start values, " + p.failure);
    p.best = phi, p.best_data = data, p.best_reaction = p.reaction, p.best_z = z;
  }

  nlopt::opt opt(nlopt::LD_LBFGS, static_cast<unsigned>(z.size()));
  const double span = std::log(1e4);
  std::vector<double> lo(z.size()), hi(z.size()), zv(z.data(), z.data() + z.size());
  for (int i = 0; i < z.size(); ++i) lo[i] = z[i] - span, hi[i] = z[i] + span;
  opt.set_lower_bounds(lo);
  opt.set_upper_bounds(hi);
  opt.set_min_objective(objective, &p);
  opt.set_ftol_rel(o.relative_tolerance);
  opt.set_maxeval(o.max_evaluations);
  DisplacementInverseResult result;
  double value = 0;
  try {
    const nlopt::result r = opt.optimize(zv, value);
    result.stop = r == nlopt::MAXEVAL_REACHED ? "evaluation budget spent" : "converged";
  } catch (const nlopt::roundoff_limited&) {
    result.stop = "converged to round-off";
  } catch (const nlopt::forced_stop&) {
    if (!p.error) throw;
  } catch (const std::runtime_error& e) {
    if (p.error) std::rethrow_exception(p.error);
    // L-BFGS gives up this way when its line search finds no descent, which at a
    // noise-free optimum is round-off too; the best point so far is kept.
    result.stop = fmt::format("optimiser failure ({}) at the best point", e.what());
  }
  if (p.error) std::rethrow_exception(p.error);
  if (p.failed > 0)
    result.stop += fmt::format(" ({} trial(s) without a static equilibrium, the last: {})",
                               p.failed, p.failure);
  for (const auto& info : law.params()) result.parameters.push_back(info.name);
  result.q.resize(p.nq, mesh.num_tets());
  for (int e = 0; e < mesh.num_tets(); ++e)
    result.q.col(e) = p.best_z.segment(p.group[e] * p.nq, p.nq).array().exp();
  result.rms = std::sqrt(2 * p.best_data / (3.0 * observed));
  int reactions = 0;
  double weight = 0;
  for (const auto& m : ms)
    if (!m.reactions.empty())
      reactions += static_cast<int>(m.reactions.size()), weight = m.reaction_weight;
  if (reactions > 0 && weight > 0)
    result.reaction_rms = std::sqrt(2 * p.best_reaction / weight / (3.0 * reactions));
  result.evaluations = p.evaluations;
  // Leave the models at the fitted values.
  for (auto& m : ms) m.model->terms()[p.term].q = result.q;
  return result;
}

}  // namespace kelvin
