#include "adjoint/marker_objective.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "engine/cubic_spline.hpp"
#include "engine/error.hpp"

namespace kelvin {

MarkerObjective::MarkerObjective(const std::vector<MarkerEmbedding>& markers,
                                 const MarkerTracks& observed, const ObjectiveSpec& spec,
                                 double t_end)
    : times_(observed.times),
      t0_(spec.window_begin),
      t1_(spec.window_end < 0 ? t_end : std::min(spec.window_end, t_end)) {
  for (size_t c = 0; c < observed.names.size(); ++c) {
    const auto it = std::find_if(markers.begin(), markers.end(), [&](const MarkerEmbedding& m) {
      return m.name == observed.names[c];
    });
    if (it == markers.end()) continue;
    const auto w = spec.weights.find(it->name);
    const double weight = w == spec.weights.end() ? 1.0 : w->second;
    if (weight == 0) continue;
    names_.push_back(it->name);
    embedding_.push_back(*it);
    weight_.push_back(weight);
    track_.push_back(observed.xyz.middleRows(3 * c, 3));
  }
  // Each run of consecutive seen frames gets its own spline: a linear track cuts the
  // corners of a 17 Hz motion sampled at 200 Hz by ~0.7 mm, a bias that fits would
  // absorb into the damping parameters, and the C1 cubic Hermite with three-frame
  // slopes this replaced left 0.024 mm RMS between the 180 Hz frames of the bench
  // bar's 35 Hz ringing where the spline leaves 0.0057 mm (both against the exact
  // motion): O(h⁴) against O(h³). Not-a-knot ends keep that order next to every gap,
  // where a first-order end slope had biased the occluded-burst fit (λ 1.5e-3 off).
  for (const auto& track : track_) {
    Eigen::Matrix3Xd& slope =
        slopes_.emplace_back(Eigen::Matrix3Xd::Constant(3, times_.size(), NAN));
    for (size_t k = 0; k < times_.size();) {
      size_t end = k;
      while (end < times_.size() && track.col(end).allFinite()) ++end;
      if (end - k >= 2) {
        const std::vector<double> t(times_.begin() + k, times_.begin() + end);
        slope.middleCols(k, end - k) =
            cubic_spline_slopes(t, track.middleCols(k, end - k), SplineEnds::kNotAKnot);
      }
      k = end + 1;
    }
  }
  weighted_time_.assign(names_.size(), 0.0);
  for (size_t i = 0; i < names_.size(); ++i)
    for (size_t k = 0; k + 1 < times_.size(); ++k) {
      if (!track_[i].col(k).allFinite() || !track_[i].col(k + 1).allFinite()) continue;
      const double a = std::max(times_[k], t0_), b = std::min(times_[k + 1], t1_);
      if (b > a) weighted_time_[i] += weight_[i] * (b - a);
    }
  double total = 0;
  for (double t : weighted_time_) total += t;
  if (total <= 0)
    throw Error(fmt::format(
        "no marker is observed in two consecutive frames inside the objective window [{:g}, "
        "{:g}] s",
        t0_, t1_));
}

bool MarkerObjective::observed(int i, double t, Eigen::Vector3d& xbar) const {
  if (t < t0_ || t > t1_ || times_.size() < 2 || t < times_.front() || t > times_.back())
    return false;
  // Left-continuous: a time equal to a frame belongs to the interval ending there.
  size_t k = std::lower_bound(times_.begin(), times_.end(), t) - times_.begin();
  k = k == 0 ? 0 : k - 1;
  const auto a = track_[i].col(k), b = track_[i].col(k + 1);
  if (!a.allFinite() || !b.allFinite()) return false;
  const double h = times_[k + 1] - times_[k];
  xbar = hermite(a, slopes_[i].col(k), b, slopes_[i].col(k + 1), (t - times_[k]) / h, h, 0);
  return true;
}

void MarkerObjective::integrand(double t, const FemModel& model, const Eigen::Matrix3Xd& x,
                                double* g) const {
  Eigen::Vector3d xbar;
  for (int i = 0; i < num_markers(); ++i) {
    g[i] = 0;
    if (!observed(i, t, xbar)) continue;
    const auto& m = embedding_[i];
    Eigen::Vector3d xs = Eigen::Vector3d::Zero();
    for (int a = 0; a < 4; ++a) xs += m.weights[a] * x.col(model.mesh().tets(a, m.tet));
    g[i] = 0.5 * weight_[i] * (xs - xbar).squaredNorm();
  }
}

void MarkerObjective::add_gradient(double t, const FemModel& model, const Eigen::Matrix3Xd& x,
                                   double* grad) const {
  Eigen::Vector3d xbar;
  for (int i = 0; i < num_markers(); ++i) {
    if (!observed(i, t, xbar)) continue;
    const auto& m = embedding_[i];
    Eigen::Vector3d xs = Eigen::Vector3d::Zero();
    for (int a = 0; a < 4; ++a) xs += m.weights[a] * x.col(model.mesh().tets(a, m.tet));
    const Eigen::Vector3d r = weight_[i] * (xs - xbar);
    for (int a = 0; a < 4; ++a)
      for (int c = 0; c < 3; ++c) {
        const int d = model.dof(model.mesh().tets(a, m.tet), c);
        if (d >= 0) grad[d] += m.weights[a] * r[c];
      }
  }
}

Eigen::VectorXd MarkerObjective::marker_rms(const Eigen::VectorXd& phi) const {
  Eigen::VectorXd rms(num_markers());
  for (int i = 0; i < num_markers(); ++i)
    rms[i] = weighted_time_[i] > 0 ? std::sqrt(2 * phi[i] / weighted_time_[i]) : NAN;
  return rms;
}

double MarkerObjective::rms(const Eigen::VectorXd& phi) const {
  double total = 0;
  for (double t : weighted_time_) total += t;
  return std::sqrt(2 * phi.sum() / total);
}

}  // namespace kelvin
