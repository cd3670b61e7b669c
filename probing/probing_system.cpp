#include "probing/probing_system.hpp"

#include <fmt/format.h>

#include <Eigen/LU>
#include <algorithm>
#include <array>

#include "base/error.hpp"
#include "engine/static_solver.hpp"

namespace kelvin {

int elastic_term(const FemModel& model) {
  int found = -1;
  for (int k = 0; k < static_cast<int>(model.terms().size()); ++k) {
    if (model.terms()[k].model->is_viscous()) continue;
    if (found >= 0)
      throw Error(
          "static probing: the material has more than one elastic term; it fits one "
          "(its parameters per element)");
    found = k;
  }
  if (found < 0) throw Error("static probing: the material has no elastic term");
  return found;
}

Eigen::Matrix3Xd static_equilibrium(const FemModel& model, const std::string& measurement) {
  Eigen::VectorXd x = rigid_initial_guess(model, 0);
  const StaticResult r = solve_static(model, 0, x);
  if (!r.converged)
    throw Error(fmt::format("measurement '{}': no static equilibrium: {}", measurement, r.message));
  Eigen::Matrix3Xd full, v;
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(x.size());
  model.expand(0, x.data(), zero.data(), full, v);
  return full;
}

std::vector<std::pair<int, int>> face_neighbours(const Mesh& mesh) {
  std::vector<std::pair<std::array<int, 3>, int>> faces;
  faces.reserve(4 * mesh.num_tets());
  for (int e = 0; e < mesh.num_tets(); ++e)
    for (int skip = 0; skip < 4; ++skip) {
      std::array<int, 3> f;
      for (int a = 0, j = 0; a < 4; ++a)
        if (a != skip) f[j++] = mesh.tets(a, e);
      std::sort(f.begin(), f.end());
      faces.emplace_back(f, e);
    }
  std::sort(faces.begin(), faces.end());
  std::vector<std::pair<int, int>> pairs;
  for (size_t i = 1; i < faces.size(); ++i)
    if (faces[i].first == faces[i - 1].first)
      pairs.emplace_back(faces[i - 1].second, faces[i].second);
  return pairs;
}

std::pair<std::vector<int>, int> element_groups(const Mesh& mesh, ElementGrouping g) {
  std::vector<int> group(mesh.num_tets(), 0);
  if (g == ElementGrouping::kGlobal) return {group, 1};
  if (g == ElementGrouping::kElement) {
    for (int e = 0; e < mesh.num_tets(); ++e) group[e] = e;
    return {group, mesh.num_tets()};
  }
  std::vector<int> labels(mesh.region.begin(), mesh.region.end());
  std::sort(labels.begin(), labels.end());
  labels.erase(std::unique(labels.begin(), labels.end()), labels.end());
  for (int e = 0; e < mesh.num_tets(); ++e)
    group[e] = static_cast<int>(std::lower_bound(labels.begin(), labels.end(), mesh.region[e]) -
                                labels.begin());
  return {group, static_cast<int>(labels.size())};
}

namespace {

/// Element e's nodal forces per parameter k of `term`, V ∂P/∂q_k G (3 × 4 each), at
/// full positions x; with require_linear, throws naming e where P ≠ Σ q ∂P/∂q.
std::vector<Eigen::Matrix<double, 3, 4>> element_parameter_forces(const FemModel& model, int term,
                                                                  const Eigen::Matrix3Xd& x, int e,
                                                                  bool require_linear,
                                                                  MaterialResponse& out) {
  const MaterialTerm& t = model.terms()[term];
  const int nq = static_cast<int>(t.model->params().size());
  const TetElement& el = model.elements()[e];
  Eigen::Matrix<double, 3, 4> xe;
  for (int a = 0; a < 4; ++a) xe.col(a) = x.col(el.nodes[a]);
  MaterialPoint p;
  p.F = xe * el.G.transpose();
  p.q = t.q.col(e).data();
  p.state = t.state.size() ? t.state.col(e).data() : nullptr;
  p.element = e;
  p.rest_tangent = model.rest_tangent(e);
  if (!t.model->evaluate(p, kStress | kParamDerivative, out))
    throw Error(fmt::format("element {} is inadmissible (det F = {:.3g}) in the measured positions",
                            e, p.F.determinant()));
  if (require_linear) {
    const Eigen::Map<const Eigen::VectorXd> q(p.q, nq);
    const double scale = out.P.norm() + (out.dPdq * q.cwiseAbs()).norm();
    if ((out.P.reshaped() - out.dPdq * q).norm() > 1e-8 * scale + 1e-300)
      throw Error(fmt::format(
          "the elastic model '{}' is not linear in its parameters (element {}: P ≠ Σ q ∂P/∂q); "
          "use one that is, such as corotational (warped stiffness)",
          t.model->name(), e));
  }
  std::vector<Eigen::Matrix<double, 3, 4>> f(nq);
  for (int k = 0; k < nq; ++k) f[k] = el.volume * out.dPdq.col(k).reshaped(3, 3) * el.G;
  return f;
}

}  // namespace

Eigen::SparseMatrix<double> force_parameter_jacobian(const FemModel& model, int term,
                                                     const Eigen::Matrix3Xd& x,
                                                     const std::vector<int>& group, int columns,
                                                     int column_offset, bool require_linear) {
  const int nq = static_cast<int>(model.terms()[term].model->params().size());
  std::vector<Eigen::Triplet<double>> entries;
  entries.reserve(12 * nq * model.mesh().num_tets());
  MaterialResponse out;
  for (int e = 0; e < model.mesh().num_tets(); ++e) {
    const auto f = element_parameter_forces(model, term, x, e, require_linear, out);
    const TetElement& el = model.elements()[e];
    for (int k = 0; k < nq; ++k) {
      const int col = column_offset + group[e] * nq + k;
      for (int a = 0; a < 4; ++a)
        for (int i = 0; i < 3; ++i) {
          const int d = model.dof(el.nodes[a], i);
          if (d >= 0 && f[k](i, a) != 0) entries.emplace_back(d, col, f[k](i, a));
        }
    }
  }
  Eigen::SparseMatrix<double> J(model.num_dofs(), columns);
  J.setFromTriplets(entries.begin(), entries.end());
  return J;
}

Eigen::Matrix3Xd reaction_parameter_jacobian(const FemModel& model, int term,
                                             const ClampReaction& press, const Eigen::Matrix3Xd& x,
                                             const std::vector<int>& group, int columns,
                                             int column_offset) {
  const int nq = static_cast<int>(model.terms()[term].model->params().size());
  Eigen::Matrix3Xd J = Eigen::Matrix3Xd::Zero(3, columns);
  MaterialResponse out;
  for (int e = 0; e < model.mesh().num_tets(); ++e) {
    const TetElement& el = model.elements()[e];
    bool touches = false;
    for (int a = 0; a < 4; ++a) touches |= press.holds(el.nodes[a]);
    if (!touches) continue;
    const auto f = element_parameter_forces(model, term, x, e, false, out);
    for (int k = 0; k < nq; ++k)
      for (int a = 0; a < 4; ++a)
        if (press.holds(el.nodes[a])) J.col(column_offset + group[e] * nq + k) += f[k].col(a);
  }
  return J;
}

}  // namespace kelvin
