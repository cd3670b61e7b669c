#include "probing/force_inverse.hpp"

#include <fmt/format.h>

#include <Eigen/SPQRSupport>
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>

#include "base/error.hpp"
#include "probing/probing_system.hpp"

namespace kelvin {
namespace {

using Triplets = std::vector<Eigen::Triplet<double>>;

struct System {
  Eigen::SparseMatrix<double> A, L;  // force rows; smoothness rows (unscaled)
  Eigen::VectorXd f;
  std::vector<std::pair<int, int>> space_pairs;
  double column_scale = 1;  // typical column norm of A
};

Eigen::VectorXd solve(const System& s, double gamma_space, double gamma_measurement, int space_rows,
                      Eigen::VectorXd* residual) {
  // [A; γ c L] θ = [f; 0]: the smoothness rows scaled to the force rows' size.
  Eigen::SparseMatrix<double> L = s.L;
  for (int k = 0; k < L.outerSize(); ++k)
    for (Eigen::SparseMatrix<double>::InnerIterator it(L, k); it; ++it)
      it.valueRef() *= s.column_scale * (it.row() < space_rows ? gamma_space : gamma_measurement);
  Eigen::SparseMatrix<double> stacked(s.A.rows() + L.rows(), s.A.cols());
  Triplets t;
  t.reserve(s.A.nonZeros() + L.nonZeros());
  for (int k = 0; k < s.A.outerSize(); ++k)
    for (Eigen::SparseMatrix<double>::InnerIterator it(s.A, k); it; ++it)
      t.emplace_back(it.row(), it.col(), it.value());
  for (int k = 0; k < L.outerSize(); ++k)
    for (Eigen::SparseMatrix<double>::InnerIterator it(L, k); it; ++it)
      if (it.value() != 0) t.emplace_back(s.A.rows() + it.row(), it.col(), it.value());
  stacked.setFromTriplets(t.begin(), t.end());
  Eigen::VectorXd b = Eigen::VectorXd::Zero(stacked.rows());
  b.head(s.f.size()) = s.f;
  Eigen::SPQR<Eigen::SparseMatrix<double>> qr;
  qr.compute(stacked);
  if (qr.info() != Eigen::Success)
    throw Error("force-based inverse: the sparse QR factorisation (SuiteSparseQR) failed");
  Eigen::VectorXd theta = qr.solve(b);
  if (qr.info() != Eigen::Success || !theta.allFinite())
    throw Error("force-based inverse: the least-squares solve (SuiteSparseQR) failed");
  if (residual) *residual = s.A * theta - s.f;
  return theta;
}

/// The L-curve's corner: in (log ‖r‖, log ‖L θ‖) the point farthest from the chord
/// between its ends, on the side of the origin (the triangle method of Castellanos
/// et al. 2002). Curvature from differences is fooled by the flat ends, where both
/// coordinates move by round-off only.
int lcurve_corner(const std::vector<LCurvePoint>& c) {
  if (c.size() < 3) return -1;
  auto at = [&](size_t i) {
    return Eigen::Vector2d(std::log(c[i].residual + 1e-300), std::log(c[i].roughness + 1e-300));
  };
  const Eigen::Vector2d p0 = at(0), chord = at(c.size() - 1) - p0;
  int best = -1;
  double best_d = 0;
  for (size_t i = 1; i + 1 < c.size(); ++i) {
    const Eigen::Vector2d w = at(i) - p0;
    const double d = chord.x() * w.y() - chord.y() * w.x();  // < 0: towards the origin
    if (d < best_d) best_d = d, best = static_cast<int>(i);
  }
  return best < 0 ? static_cast<int>(c.size()) / 2 : best;
}

}  // namespace

double youngs_modulus(double lambda, double mu) {
  return mu * (3 * lambda + 2 * mu) / (lambda + mu);
}
double poissons_ratio(double lambda, double mu) {
  return lambda / (2 * (lambda + mu));
}

ForceInverseResult force_based_inverse(const std::vector<StaticState>& ms,
                                       const ForceInverseOptions& o) {
  if (ms.empty()) throw Error("force-based inverse: no measurement");
  const FemModel& first = *ms[0].model;
  const Mesh& mesh = first.mesh();
  const int term = elastic_term(first);
  const Material& law = *first.terms()[term].model;
  const int nq = static_cast<int>(law.params().size());
  for (size_t m = 0; m < ms.size(); ++m) {
    const FemModel& model = *ms[m].model;
    if (model.mesh().num_tets() != mesh.num_tets() ||
        model.mesh().num_nodes() != mesh.num_nodes() || elastic_term(model) != term ||
        model.terms()[term].model->name() != law.name())
      throw Error(fmt::format(
          "force-based inverse: measurement {} is of another mesh or material than the first", m));
    for (const auto& c : model.clamps())
      if (c.compliant())
        throw Error(fmt::format(
            "force-based inverse: clamp '{}' is compliant; supports must hold their nodes",
            c.name));
    if (ms[m].x.cols() != mesh.num_nodes() || !ms[m].x.allFinite())
      throw Error(fmt::format(
          "force-based inverse: measurement {} needs a finite position for each of the {} nodes", m,
          mesh.num_nodes()));
  }
  const auto [group, groups] = element_groups(mesh, o.grouping);
  const int sets = o.per_measurement ? static_cast<int>(ms.size()) : 1;
  const int columns = sets * groups * nq;

  System s;
  std::vector<Eigen::SparseMatrix<double>> blocks;
  std::vector<Eigen::VectorXd> loads;
  int n_rows = 0;
  for (size_t m = 0; m < ms.size(); ++m) {
    const int set = o.per_measurement ? static_cast<int>(m) : 0;
    const FemModel& model = *ms[m].model;
    try {
      Eigen::SparseMatrix<double> rows =
          force_parameter_jacobian(model, term, ms[m].x, group, columns, set * groups * nq, true);
      const int n = static_cast<int>(rows.rows()),
                extra = 3 * static_cast<int>(ms[m].reactions.size());
      Eigen::VectorXd f(n + extra);
      f.head(n) = model.external_force();
      if (extra > 0) {
        Triplets t;
        for (int k = 0; k < rows.outerSize(); ++k)
          for (Eigen::SparseMatrix<double>::InnerIterator it(rows, k); it; ++it)
            t.emplace_back(it.row(), it.col(), it.value());
        for (int r = 0; r < extra / 3; ++r) {
          const auto& [clamp, seen] = ms[m].reactions[r];
          const ClampReaction press(model, clamp);
          const Eigen::Matrix3Xd held = reaction_parameter_jacobian(
              model, term, press, ms[m].x, group, columns, set * groups * nq);
          for (int c = 0; c < columns; ++c)
            for (int i = 0; i < 3; ++i)
              if (held(i, c) != 0) t.emplace_back(n + 3 * r + i, c, held(i, c));
          f.segment<3>(n + 3 * r) = seen + press.weight();
        }
        rows.resize(n + extra, columns);
        rows.setFromTriplets(t.begin(), t.end());
      }
      n_rows += static_cast<int>(rows.rows());
      blocks.push_back(std::move(rows));
      loads.push_back(std::move(f));
    } catch (const Error& e) {
      throw Error(fmt::format("force-based inverse: measurement {}: {}", m, e.what()));
    }
  }
  s.A.resize(n_rows, columns);
  {
    Triplets rows;
    int offset = 0;
    for (const auto& b : blocks) {
      for (int k = 0; k < b.outerSize(); ++k)
        for (Eigen::SparseMatrix<double>::InnerIterator it(b, k); it; ++it)
          rows.emplace_back(offset + it.row(), it.col(), it.value());
      offset += b.rows();
    }
    s.A.setFromTriplets(rows.begin(), rows.end());
  }
  s.f.resize(n_rows);
  for (size_t m = 0, r = 0; m < ms.size(); r += loads[m].size(), ++m)
    s.f.segment(r, loads[m].size()) = loads[m];
  if (s.f.norm() == 0) throw Error("force-based inverse: the measurements carry no load");
  s.column_scale = s.A.norm() / std::sqrt(double(columns));

  // Smoothness: across shared faces within each set, then between consecutive sets.
  Triplets smooth;
  int space_rows = 0;
  if (o.grouping == ElementGrouping::kElement) {
    s.space_pairs = face_neighbours(mesh);
    for (int set = 0; set < sets; ++set)
      for (const auto& [e, f] : s.space_pairs)
        for (int k = 0; k < nq; ++k, ++space_rows) {
          smooth.emplace_back(space_rows, (set * groups + e) * nq + k, 1.0);
          smooth.emplace_back(space_rows, (set * groups + f) * nq + k, -1.0);
        }
  }
  int measurement_rows = 0;
  for (int set = 0; set + 1 < sets; ++set)
    for (int g = 0; g < groups; ++g)
      for (int k = 0; k < nq; ++k, ++measurement_rows) {
        const int r = space_rows + measurement_rows;
        smooth.emplace_back(r, (set * groups + g) * nq + k, 1.0);
        smooth.emplace_back(r, ((set + 1) * groups + g) * nq + k, -1.0);
      }
  s.L.resize(space_rows + measurement_rows, columns);
  s.L.setFromTriplets(smooth.begin(), smooth.end());

  ForceInverseResult result;
  for (const auto& p : law.params()) result.parameters.push_back(p.name);
  double gamma = std::max(o.gamma_space, 0.0);
  if (space_rows > 0 && o.gamma_space < 0) {
    std::vector<double> grid = o.lcurve;
    if (grid.empty())
      for (int i = -12; i <= 2; ++i) grid.push_back(std::pow(10.0, i / 2.0));
    const Eigen::SparseMatrix<double> Ls = s.L.topRows(space_rows);
    for (double g : grid) {
      Eigen::VectorXd r;
      const Eigen::VectorXd theta = solve(s, g, o.gamma_measurement, space_rows, &r);
      result.lcurve.push_back({g, r.norm(), (Ls * theta).norm()});
    }
    const int corner = lcurve_corner(result.lcurve);
    if (corner < 0)
      throw Error("force-based inverse: the L-curve needs at least three values of γ");
    gamma = result.lcurve[corner].gamma;
  }
  Eigen::VectorXd r;
  const Eigen::VectorXd theta = solve(s, gamma, o.gamma_measurement, space_rows, &r);
  result.gamma_space = gamma;
  result.relative_residual = r.norm() / s.f.norm();
  for (int set = 0; set < sets; ++set) {
    Eigen::MatrixXd q(nq, mesh.num_tets());
    for (int e = 0; e < mesh.num_tets(); ++e)
      q.col(e) = theta.segment((set * groups + group[e]) * nq, nq);
    result.q.push_back(std::move(q));
  }
  return result;
}

}  // namespace kelvin
