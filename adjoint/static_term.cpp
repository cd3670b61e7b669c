#include "adjoint/static_term.hpp"

#include <fmt/format.h>

#include <Eigen/CholmodSupport>
#include <Eigen/KLUSupport>
#include <cmath>
#include <memory>

#include "engine/param_derivatives.hpp"
#include "engine/static_solver.hpp"

namespace kelvin {

StaticTerm::StaticTerm(FemModel& model, std::string name, std::vector<MarkerEmbedding> markers,
                       Eigen::Matrix3Xd observed, double weight,
                       std::vector<std::pair<int, Eigen::Vector3d>> reactions,
                       double reaction_weight)
    : model_(model),
      name_(std::move(name)),
      markers_(std::move(markers)),
      observed_(std::move(observed)),
      weight_(weight),
      reactions_(std::move(reactions)),
      reaction_weight_(reaction_weight) {
  for (int j = 0; j < observed_.cols(); ++j) observed_count_ += observed_.col(j).allFinite();
  x_free_ = rigid_initial_guess(model_, 0);
}

bool StaticTerm::equilibrium(const ParameterMap& map, const Eigen::VectorXd& p, Eigen::Matrix3Xd& x,
                             std::string& error) {
  map.apply(p, model_);
  StaticResult s = solve_static(model_, 0, x_free_);
  if (!s.converged) {  // the last equilibrium may be a poor start for these parameters
    x_free_ = rigid_initial_guess(model_, 0);
    s = solve_static(model_, 0, x_free_);
  }
  if (!s.converged) {
    error = fmt::format("static measurement '{}': {}", name_, s.message);
    return false;
  }
  Eigen::Matrix3Xd v;
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(x_free_.size());
  model_.expand(0, x_free_.data(), zero.data(), x, v);
  return true;
}

bool StaticTerm::factor_stiffness(const Eigen::Matrix3Xd& x, std::string& error) {
  AssemblyRequest req;
  req.force = false, req.stiffness = true;
  AssemblyOutput k;
  const Eigen::Matrix3Xd v = Eigen::Matrix3Xd::Zero(3, x.cols());
  if (!model_.assemble(x, v, req, k)) {
    error = fmt::format("static measurement '{}': element {} is inadmissible at equilibrium", name_,
                        k.failed_element);
    return false;
  }
  const Eigen::SparseMatrix<double> K = to_sparse_matrix(model_.pattern(), k.K);
  // K is symmetric positive definite at a stable equilibrium; LU where it is not.
  using Cholesky = Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower>;
  auto cholesky = std::make_shared<Cholesky>();
  cholesky->cholmod().print = 0;
  cholesky->compute(K);
  if (cholesky->info() == Eigen::Success) {
    solve_ = [cholesky](const Eigen::VectorXd& b) -> Eigen::VectorXd { return cholesky->solve(b); };
    return true;
  }
  auto klu = std::make_shared<Eigen::KLU<Eigen::SparseMatrix<double>>>(K);
  if (klu->info() == Eigen::Success) {
    solve_ = [klu](const Eigen::VectorXd& b) -> Eigen::VectorXd { return klu->solve(b); };
    return true;
  }
  error = fmt::format("static measurement '{}': the stiffness at equilibrium is singular", name_);
  return false;
}

std::string StaticTerm::inadmissible(const ClampReaction& press) const {
  return fmt::format("static measurement '{}': element {} is inadmissible at equilibrium", name_,
                     press.failed_element);
}

bool StaticTerm::reaction_misfits(const Eigen::Matrix3Xd& x, std::vector<Eigen::Vector3d>& misfit,
                                  std::string& error) const {
  misfit.clear();
  for (const auto& [clamp, seen] : reactions_) {
    const ClampReaction press(model_, clamp);
    Eigen::Vector3d R;
    if (!press.force(x, R)) {
      error = inadmissible(press);
      return false;
    }
    misfit.push_back(R - seen);
  }
  return true;
}

StaticTermResult StaticTerm::evaluate(const ParameterMap& map, const Eigen::VectorXd& p,
                                      bool gradient) {
  StaticTermResult out;
  Eigen::Matrix3Xd x;
  if (!equilibrium(map, p, x, out.error)) return out;
  const Mesh& mesh = model_.mesh();
  const Eigen::Matrix3Xd at = marker_positions(mesh, markers_, x);
  Eigen::Matrix3Xd pull = Eigen::Matrix3Xd::Zero(3, mesh.num_nodes());
  double sum = 0;
  for (int j = 0; j < at.cols(); ++j) {
    if (!observed_.col(j).allFinite()) continue;
    const Eigen::Vector3d r = at.col(j) - observed_.col(j);
    sum += r.squaredNorm();
    for (int a = 0; a < 4; ++a)
      pull.col(mesh.tets(a, markers_[j].tet)) += weight_ * markers_[j].weights[a] * r;
  }
  out.phi = 0.5 * weight_ * sum;
  out.rms = observed_count_ ? std::sqrt(sum / observed_count_) : 0;
  std::vector<Eigen::Vector3d> misfit;
  if (!reaction_misfits(x, misfit, out.error)) return out;
  for (const auto& dR : misfit) out.phi += 0.5 * weight_ * reaction_weight_ * dR.squaredNorm();
  out.ok = true;
  if (!gradient) return out;

  if (!factor_stiffness(x, out.error)) {
    out.ok = false;
    return out;
  }
  Eigen::VectorXd rhs(model_.num_dofs());
  model_.restrict(pull, rhs.data());
  // μ: the held dofs' weights in the parameter derivative, −w c ΔR at each held node.
  Eigen::Matrix3Xd held = Eigen::Matrix3Xd::Zero(3, mesh.num_nodes());
  for (size_t k = 0; k < reactions_.size(); ++k) {
    const ClampReaction press(model_, reactions_[k].first);
    const Eigen::Vector3d w = weight_ * reaction_weight_ * misfit[k];
    if (!press.add_position_adjoint(x, w, rhs)) {
      out.ok = false;
      out.error = inadmissible(press);
      return out;
    }
    for (int a : model_.clamps()[reactions_[k].first].nodes) held.col(a) -= w;
  }
  const Eigen::VectorXd lambda = solve_(rhs);
  if (!lambda.allFinite()) {
    out.ok = false;
    out.error = fmt::format("static measurement '{}': the adjoint solve failed", name_);
    return out;
  }
  out.gradient = Eigen::VectorXd::Zero(map.size());
  ParamDerivatives deriv(model_, map.slots());
  const auto& elements = model_.elements();
  const Eigen::Matrix3Xd v = Eigen::Matrix3Xd::Zero(3, mesh.num_nodes());
  const bool ok = deriv.for_each(0, x, v, v, [&](int e, int s, const Vec12& dR) {
    double c = 0;
    for (int i = 0; i < 12; ++i) {
      const int node = elements[e].nodes[i / 3];
      if (const int d = model_.dof(node, i % 3); d >= 0)
        c += lambda[d] * dR[i];
      else
        c += held(i % 3, node) * dR[i];
    }
    map.for_each_dependency(p, s, e, [&](int j, double dq) { out.gradient[j] -= c * dq; });
  });
  if (!ok) {
    out.ok = false;
    out.error = fmt::format("static measurement '{}': a material rejects the equilibrium", name_);
  }
  return out;
}

bool StaticTerm::residuals(const ParameterMap& map, const Eigen::VectorXd& p, bool with_jacobian,
                           Eigen::VectorXd& r, Eigen::MatrixXd& jacobian,
                           std::vector<std::pair<int, int>>& coordinates, std::string& error) {
  Eigen::Matrix3Xd x;
  if (!equilibrium(map, p, x, error)) return false;
  const Mesh& mesh = model_.mesh();
  const Eigen::Matrix3Xd at = marker_positions(mesh, markers_, x);
  coordinates.clear();
  std::vector<double> values;
  for (int j = 0; j < at.cols(); ++j)
    for (int c = 0; c < 3; ++c)
      if (std::isfinite(observed_(c, j))) {
        coordinates.emplace_back(j, c);
        values.push_back(at(c, j) - observed_(c, j));
      }
  std::vector<Eigen::Vector3d> misfit;
  if (!reaction_misfits(x, misfit, error)) return false;
  const double root_c = std::sqrt(reaction_weight_);
  const int marker_rows = static_cast<int>(values.size());
  for (size_t k = 0; k < misfit.size(); ++k)
    for (int c = 0; c < 3; ++c) {
      coordinates.emplace_back(-1 - static_cast<int>(k), c);
      values.push_back(root_c * misfit[k][c]);
    }
  r = Eigen::Map<const Eigen::VectorXd>(values.data(), static_cast<Eigen::Index>(values.size()));
  jacobian.resize(0, map.size());
  if (!with_jacobian) return true;
  if (!factor_stiffness(x, error)) return false;
  // Per reaction: (∂R/∂x_free)ᵀ.
  std::vector<Eigen::Matrix<double, Eigen::Dynamic, 3>> dR_dx(reactions_.size());
  for (size_t k = 0; k < reactions_.size(); ++k) {
    const ClampReaction press(model_, reactions_[k].first);
    if (!press.position_rows(x, dR_dx[k])) {
      error = inadmissible(press);
      return false;
    }
  }
  // B = ∂R/∂p over the free dofs, then dx/dp = −K⁻¹ B column by column.
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(model_.num_dofs(), map.size());
  // The held nodes' rows of ∂r/∂p: node → its reactions (ΔR/Δp directly).
  std::vector<Eigen::MatrixXd> held_rows(reactions_.size(), Eigen::MatrixXd::Zero(3, map.size()));
  std::vector<std::vector<int>> holders(mesh.num_nodes());
  for (size_t k = 0; k < reactions_.size(); ++k)
    for (int a : model_.clamps()[reactions_[k].first].nodes)
      holders[a].push_back(static_cast<int>(k));
  ParamDerivatives deriv(model_, map.slots());
  const auto& elements = model_.elements();
  const Eigen::Matrix3Xd v = Eigen::Matrix3Xd::Zero(3, mesh.num_nodes());
  const bool ok = deriv.for_each(0, x, v, v, [&](int e, int s, const Vec12& dR) {
    map.for_each_dependency(p, s, e, [&](int j, double dq) {
      for (int i = 0; i < 12; ++i) {
        const int node = elements[e].nodes[i / 3];
        if (const int d = model_.dof(node, i % 3); d >= 0)
          B(d, j) += dq * dR[i];
        else
          for (int k : holders[node]) held_rows[k](i % 3, j) += dq * dR[i];
      }
    });
  });
  if (!ok) {
    error = fmt::format("static measurement '{}': a material rejects the equilibrium", name_);
    return false;
  }
  jacobian.setZero(static_cast<Eigen::Index>(coordinates.size()), map.size());
  for (int j = 0; j < map.size(); ++j) {
    const Eigen::VectorXd dx = -solve_(B.col(j));
    for (int k = 0; k < marker_rows; ++k) {
      const auto [m, c] = coordinates[k];
      for (int a = 0; a < 4; ++a)
        if (const int d = model_.dof(mesh.tets(a, markers_[m].tet), c); d >= 0)
          jacobian(k, j) += markers_[m].weights[a] * dx[d];
    }
    for (size_t k = 0; k < reactions_.size(); ++k)
      jacobian.block<3, 1>(marker_rows + 3 * static_cast<int>(k), j) =
          root_c * (held_rows[k].col(j) + dR_dx[k].transpose() * dx);
  }
  return true;
}

}  // namespace kelvin
