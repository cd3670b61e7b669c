#include "adjoint/static_term.hpp"

#include <fmt/format.h>

#include <Eigen/CholmodSupport>
#include <Eigen/KLUSupport>
#include <cmath>

#include "engine/param_derivatives.hpp"
#include "engine/static_solver.hpp"

namespace kelvin {

StaticTerm::StaticTerm(FemModel& model, std::string name, std::vector<MarkerEmbedding> markers,
                       Eigen::Matrix3Xd observed, double weight)
    : model_(model),
      name_(std::move(name)),
      markers_(std::move(markers)),
      observed_(std::move(observed)),
      weight_(weight) {
  for (int j = 0; j < observed_.cols(); ++j) observed_count_ += observed_.col(j).allFinite();
  x_free_ = rigid_initial_guess(model_, 0);
}

StaticTermResult StaticTerm::evaluate(const ParameterMap& map, const Eigen::VectorXd& p,
                                      bool gradient) {
  StaticTermResult out;
  map.apply(p, model_);
  StaticResult s = solve_static(model_, 0, x_free_);
  if (!s.converged) {  // the last equilibrium may be a poor start for these parameters
    x_free_ = rigid_initial_guess(model_, 0);
    s = solve_static(model_, 0, x_free_);
  }
  if (!s.converged) {
    out.error = fmt::format("static measurement '{}': {}", name_, s.message);
    return out;
  }
  const Mesh& mesh = model_.mesh();
  Eigen::Matrix3Xd x, v;
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(x_free_.size());
  model_.expand(0, x_free_.data(), zero.data(), x, v);
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
  out.ok = true;
  if (!gradient) return out;

  AssemblyRequest req;
  req.force = false, req.stiffness = true;
  AssemblyOutput k;
  if (!model_.assemble(x, v, req, k)) {
    out.ok = false;
    out.error = fmt::format("static measurement '{}': element {} is inadmissible at equilibrium",
                            name_, k.failed_element);
    return out;
  }
  const Eigen::SparseMatrix<double> K = to_sparse_matrix(model_.pattern(), k.K);
  Eigen::VectorXd rhs(model_.num_dofs()), lambda;
  model_.restrict(pull, rhs.data());
  // K is symmetric positive definite at a stable equilibrium; LU where it is not.
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> cholesky;
  cholesky.cholmod().print = 0;
  cholesky.compute(K);
  if (cholesky.info() == Eigen::Success) {
    lambda = cholesky.solve(rhs);
  } else {
    Eigen::KLU<Eigen::SparseMatrix<double>> klu(K);
    if (klu.info() == Eigen::Success) lambda = klu.solve(rhs);
  }
  if (lambda.size() == 0 || !lambda.allFinite()) {
    out.ok = false;
    out.error =
        fmt::format("static measurement '{}': the stiffness at equilibrium is singular", name_);
    return out;
  }
  out.gradient = Eigen::VectorXd::Zero(map.size());
  ParamDerivatives deriv(model_, map.slots());
  const auto& elements = model_.elements();
  const Eigen::Matrix3Xd a = Eigen::Matrix3Xd::Zero(3, mesh.num_nodes());
  const bool ok = deriv.for_each(0, x, v, a, [&](int e, int s, const Vec12& dR) {
    double c = 0;
    for (int i = 0; i < 12; ++i)
      if (const int d = model_.dof(elements[e].nodes[i / 3], i % 3); d >= 0) c += lambda[d] * dR[i];
    map.for_each_dependency(p, s, e, [&](int j, double dq) { out.gradient[j] -= c * dq; });
  });
  if (!ok) {
    out.ok = false;
    out.error = fmt::format("static measurement '{}': a material rejects the equilibrium", name_);
  }
  return out;
}

}  // namespace kelvin
