#include "probing/blending.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "base/error.hpp"
#include "engine/element.hpp"
#include "engine/static_solver.hpp"
#include "probing/probing_system.hpp"

namespace kelvin {
namespace {

/// The median of the distances from each set to its nearest other set, over the
/// ones that differ (two sets at one strain level must not switch the blend off);
/// 0 without any.
double median_nearest(const std::vector<double>& nearest) {
  std::vector<double> v;
  for (double d : nearest)
    if (d > 0 && std::isfinite(d)) v.push_back(d);
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

Eigen::Vector3d centroid(const Mesh& mesh, int e) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int a = 0; a < 4; ++a) c += mesh.nodes.col(mesh.tets(a, e));
  return c / 4;
}

}  // namespace

Eigen::MatrixXd element_strains(const Mesh& mesh, const Eigen::Matrix3Xd& x) {
  Eigen::MatrixXd E(6, mesh.num_tets());
  const double r2 = std::sqrt(2.0);
  for (int e = 0; e < mesh.num_tets(); ++e) {
    const TetElement el = make_tet_element(mesh, e);
    Eigen::Matrix3d F = Eigen::Matrix3d::Zero();
    for (int a = 0; a < 4; ++a) F += x.col(el.nodes[a]) * el.G.col(a).transpose();
    const Eigen::Matrix3d G = 0.5 * (F.transpose() * F - Eigen::Matrix3d::Identity());
    E.col(e) << G(0, 0), G(1, 1), G(2, 2), r2 * G(1, 2), r2 * G(0, 2), r2 * G(0, 1);
  }
  return E;
}

double strain_level(const Mesh& mesh, const Eigen::MatrixXd& strain) {
  double num = 0, den = 0;
  for (int e = 0; e < mesh.num_tets(); ++e) {
    const double v = std::abs(tet_volume(mesh, e)), s = strain.col(e).norm();
    num += v * s * s * s, den += v * s * s;
  }
  return den > 0 ? num / den : 0;
}

Blender::Blender(const Mesh& mesh, std::vector<ParameterSet> sets, const BlendOptions& options)
    : mesh_(mesh), sets_(std::move(sets)), options_(options) {
  const int ne = mesh.num_tets();
  if (sets_.empty()) throw Error("blending: no parameter sets");
  for (const auto& s : sets_)
    if (s.q.cols() != ne || s.strain.cols() != ne || s.strain.rows() != 6 ||
        s.q.rows() != sets_[0].q.rows())
      throw Error(fmt::format(
          "blending: set '{}' holds {} × {} parameters and {} strains for a mesh of {} elements",
          s.name, s.q.rows(), s.q.cols(), s.strain.cols(), ne));
    else if (!(s.q.array() > 0).all())
      throw Error(
          fmt::format("blending: set '{}' has a parameter ≤ 0 (they blend in log space)", s.name));
  volume_.resize(ne);
  for (int e = 0; e < ne; ++e) volume_[e] = std::abs(tet_volume(mesh, e));
  const int n = static_cast<int>(sets_.size());

  if (options_.metric == BlendMetric::kGlobal) {
    for (const auto& s : sets_) level_.push_back(strain_level(mesh, s.strain));
    std::vector<double> nearest;
    for (int m = 0; m < n; ++m) {
      double d = INFINITY;
      for (int k = 0; k < n; ++k)
        if (k != m) d = std::min(d, std::abs(level_[m] - level_[k]));
      if (n > 1) nearest.push_back(d);
    }
    h_ = median_nearest(nearest);
  } else {
    const double r = options_.radius > 0 ? options_.radius : 2 * std::cbrt(volume_.mean());
    std::vector<Eigen::Vector3d> c(ne);
    for (int e = 0; e < ne; ++e) c[e] = centroid(mesh, e);
    near_.resize(ne);
    for (int e = 0; e < ne; ++e) {
      double sum = 0;
      for (int j = 0; j < ne; ++j) {
        const double d2 = (c[j] - c[e]).squaredNorm() / (r * r);
        if (d2 > 9) continue;  // beyond 3 radii the Gaussian is below 1 %
        const double g = std::exp(-0.5 * d2) * volume_[j];
        near_[e].emplace_back(j, g), sum += g;
      }
      for (auto& [j, g] : near_[e]) g /= sum;
    }
    // The sets' spacing: per element, the distance to the nearest other set.
    std::vector<double> nearest;
    for (int m = 0; m < n && n > 1; ++m) {
      const Eigen::MatrixXd d2 = squared_distances(sets_[m].strain);
      for (int e = 0; e < ne; ++e) {
        double d = INFINITY;
        for (int k = 0; k < n; ++k)
          if (k != m) d = std::min(d, d2(k, e));
        nearest.push_back(std::sqrt(d));
      }
    }
    h_ = median_nearest(nearest);
  }
  // Identical sets (or one): every set weighs the same wherever the body is.
  if (!(h_ > 0)) h_ = INFINITY;
}

Eigen::MatrixXd Blender::squared_distances(const Eigen::MatrixXd& strain) const {
  const int n = static_cast<int>(sets_.size()), ne = mesh_.num_tets();
  Eigen::MatrixXd d2(n, ne);
  if (options_.metric == BlendMetric::kGlobal) {
    const double s = strain_level(mesh_, strain);
    for (int m = 0; m < n; ++m) d2.row(m).setConstant((s - level_[m]) * (s - level_[m]));
    return d2;
  }
  for (int m = 0; m < n; ++m) {
    const Eigen::VectorXd own = (strain - sets_[m].strain).colwise().squaredNorm().transpose();
    for (int e = 0; e < ne; ++e) {
      double sum = 0;
      for (const auto& [j, g] : near_[e]) sum += g * own[j];
      d2(m, e) = sum;
    }
  }
  return d2;
}

Eigen::MatrixXd Blender::weights(const Eigen::MatrixXd& strain) const {
  const Eigen::MatrixXd d2 = squared_distances(strain);
  Eigen::MatrixXd w(d2.rows(), d2.cols());
  for (int e = 0; e < d2.cols(); ++e) {
    // Shifted by the nearest set's distance: the nearest weighs 1 before normalising,
    // so no column underflows however far the strain is from every set.
    const double nearest = d2.col(e).minCoeff();
    for (int m = 0; m < d2.rows(); ++m)
      w(m, e) = std::isinf(h_) ? 1.0 : std::exp(-(d2(m, e) - nearest) / (2 * h_ * h_));
    w.col(e) /= w.col(e).sum();
  }
  return w;
}

Eigen::MatrixXd Blender::parameters(const Eigen::MatrixXd& w) const {
  Eigen::MatrixXd log_q = Eigen::MatrixXd::Zero(sets_[0].q.rows(), sets_[0].q.cols());
  for (size_t m = 0; m < sets_.size(); ++m)
    log_q += sets_[m].q.array().log().matrix() * w.row(m).asDiagonal();
  return log_q.array().exp();
}

BlendedEquilibrium blended_equilibrium(FemModel& model, const Blender& blender) {
  const BlendOptions& options = blender.options();
  const Mesh& mesh = model.mesh();
  const int term = elastic_term(model);
  BlendedEquilibrium out;
  Eigen::VectorXd x_free = rigid_initial_guess(model, 0);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(x_free.size());
  Eigen::Matrix3Xd x = mesh.nodes, v;
  auto solve = [&](double fraction) {
    StaticOptions so;
    so.load_fraction = fraction;
    const StaticResult r = solve_static(model, 0, x_free, so);
    if (!r.converged)
      out.message =
          fmt::format("no equilibrium at {:.0f} % of the load: {}", 100 * fraction, r.message);
    model.expand(0, x_free.data(), zero.data(), x, v, fraction);
    return r.converged;
  };
  // Increments: the weights of each from the strain the one before left.
  const int increments = std::max(options.increments, 1);
  for (int k = 1; k <= increments; ++k) {
    out.weights = blender.weights(element_strains(mesh, x));
    model.terms()[term].q = blender.parameters(out.weights);
    if (!solve(static_cast<double>(k) / increments)) return out;
  }
  // At the full load, until the weights the strain asks for are the ones it was made
  // with. Each pass moves halfway to them (a Mann iteration): a plain fixed-point
  // iteration can cycle between two sets when their strain levels are close.
  for (out.passes = 0; out.passes < options.max_passes; ++out.passes) {
    const Eigen::MatrixXd w = blender.weights(element_strains(mesh, x));
    out.change = (w - out.weights).cwiseAbs().maxCoeff();
    if (out.change <= options.tolerance) break;
    out.weights = out.passes == 0 ? w : 0.5 * (w + out.weights);
    model.terms()[term].q = blender.parameters(out.weights);
    if (!solve(1.0)) return out;
  }
  out.q = model.terms()[term].q;
  out.x = x;
  out.converged = out.change <= options.tolerance;
  if (!out.converged)
    out.message = fmt::format("the blend weights still change by {:.2g} after {} passes",
                              out.change, out.passes);
  return out;
}

}  // namespace kelvin
