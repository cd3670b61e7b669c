#include "adjoint/marker_objective.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "base/error.hpp"
#include "engine/cubic_spline.hpp"

namespace kelvin {

MarkerObjective::MarkerObjective(const std::vector<MarkerEmbedding>& markers,
                                 const MarkerTracks& observed, const ObjectiveSpec& spec,
                                 double t_end, bool may_be_empty)
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
  // Each frame's seen run (first and last frame), for evaluating a shifted clock.
  for (const auto& track : track_) {
    std::vector<int>& first = run_first_.emplace_back(times_.size(), -1);
    std::vector<int>& last = run_last_.emplace_back(times_.size(), -1);
    for (size_t k = 0; k < times_.size();) {
      size_t end = k;
      while (end < times_.size() && track.col(end).allFinite()) ++end;
      for (size_t j = k; j < end; ++j) {
        first[j] = static_cast<int>(k);
        last[j] = static_cast<int>(end) - 1;
      }
      k = end + 1;
    }
  }
  // The registration rotates about the tracks' mean position, so that its rotation
  // and translation are nearly independent wherever the capture frame's origin is.
  long seen = 0;
  for (const auto& track : track_)
    for (int k = 0; k < track.cols(); ++k)
      if (track.col(k).allFinite()) {
        centroid_ += track.col(k);
        ++seen;
      }
  if (seen > 0) centroid_ /= static_cast<double>(seen);
  weighted_time_.assign(names_.size(), 0.0);
  for (size_t i = 0; i < names_.size(); ++i)
    for (size_t k = 0; k + 1 < times_.size(); ++k) {
      if (!track_[i].col(k).allFinite() || !track_[i].col(k + 1).allFinite()) continue;
      const double a = std::max(times_[k], t0_), b = std::min(times_[k + 1], t1_);
      if (b > a) weighted_time_[i] += weight_[i] * (b - a);
    }
  double total = 0;
  for (double t : weighted_time_) total += t;
  if (total <= 0 && !may_be_empty)
    throw Error(fmt::format(
        "no marker is observed in two consecutive frames inside the objective window [{:g}, "
        "{:g}] s",
        t0_, t1_));
}

namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d S;
  S << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return S;
}

/// exp([ω]×) (Rodrigues) and the right Jacobian J_r(ω), with which
/// ∂(R v)/∂ω = −R [v]× J_r: series near ω = 0 keep both exact to rounding.
void rotation_and_jacobian(const Eigen::Vector3d& w, Eigen::Matrix3d& R, Eigen::Matrix3d& Jr) {
  const double th = w.norm();
  const Eigen::Matrix3d W = skew(w), W2 = W * W;
  double a, b, c;  // sin θ/θ, (1 − cos θ)/θ², (θ − sin θ)/θ³
  if (th < 1e-4) {
    const double t2 = th * th;
    a = 1 - t2 / 6;
    b = 0.5 - t2 / 24;
    c = 1.0 / 6 - t2 / 120;
  } else {
    a = std::sin(th) / th;
    b = (1 - std::cos(th)) / (th * th);
    c = (th - std::sin(th)) / (th * th * th);
  }
  R = Eigen::Matrix3d::Identity() + a * W + b * W2;
  Jr = Eigen::Matrix3d::Identity() - b * W + c * W2;
}

}  // namespace

void MarkerObjective::set_observation(const ObservationParams& params) {
  obs_ = params;
  if (obs_.marker_offsets.cols() != num_markers())
    obs_.marker_offsets = Eigen::Matrix3Xd::Zero(3, num_markers());
  rotation_and_jacobian(obs_.rotation, R_, Jr_);
}

Eigen::VectorXd MarkerObjective::observation_vector() const {
  Eigen::VectorXd theta = Eigen::VectorXd::Zero(num_observation_parameters());
  theta[0] = obs_.clock_offset;
  if (obs_.marker_offsets.cols() == num_markers())
    theta.segment(1, 3 * num_markers()) = obs_.marker_offsets.reshaped();
  theta.segment<3>(1 + 3 * num_markers()) = obs_.rotation;
  theta.segment<3>(4 + 3 * num_markers()) = obs_.translation;
  return theta;
}

void MarkerObjective::set_observation_vector(const Eigen::VectorXd& theta) {
  ObservationParams p;
  p.clock_offset = theta[0];
  p.marker_offsets = theta.segment(1, 3 * num_markers()).reshaped(3, num_markers());
  p.rotation = theta.segment<3>(1 + 3 * num_markers());
  p.translation = theta.segment<3>(4 + 3 * num_markers());
  set_observation(p);
}

bool MarkerObjective::observed(int i, double t, double offset, Eigen::Vector3d& xbar,
                               Eigen::Vector3d* rate, double* presence,
                               double* presence_rate) const {
  if (presence) *presence = 1;
  if (presence_rate) *presence_rate = 0;
  if (t < t0_ || t > t1_ || times_.size() < 2 || t < times_.front() || t > times_.back())
    return false;
  // Left-continuous: a time equal to a frame belongs to the interval ending there.
  size_t k = std::lower_bound(times_.begin(), times_.end(), t) - times_.begin();
  k = k == 0 ? 0 : k - 1;
  if (!track_[i].col(k).allFinite() || !track_[i].col(k + 1).allFinite()) return false;
  const double s = t + offset;
  if (offset != 0) {
    // A shifted clock reads the run seen around t, never across a gap. Past the run's
    // ends its tangent continues and the residual's weight falls smoothly to 0 within
    // one frame interval: the end cubics of noisy tracks, extrapolated 3.6 frames for
    // V09's 20 ms lag, had put the fit's misfit at 22 ms above the one at 0.
    const int first = run_first_[i][k], last = run_last_[i][k];
    const double begin = times_[first], finish = times_[last];
    if (s < begin || s > finish) {
      const bool after = s > finish;
      const int end = after ? last : first;
      const double h = after ? finish - times_[last - 1] : times_[first + 1] - begin;
      // Beyond one interval the residual's weight is 0, but the interval still
      // counts: Φ at every clock offset integrates over the intervals of τ = 0.
      const double q = std::min((after ? s - finish : begin - s) / h, 1.0);
      if (presence) *presence = 1 - q * q * (3 - 2 * q);
      if (presence_rate) *presence_rate = 6 * q * (q - 1) / h * (after ? 1 : -1);
      const auto slope = slopes_[i].col(end);
      xbar = track_[i].col(end) + slope * (s - times_[end]);
      if (rate) *rate = slope;
      return true;
    }
    const size_t j = std::lower_bound(times_.begin(), times_.end(), s) - times_.begin();
    k = static_cast<size_t>(std::clamp(static_cast<int>(j == 0 ? 0 : j - 1), first, last - 1));
  }
  const double h = times_[k + 1] - times_[k], u = (s - times_[k]) / h;
  const auto a = track_[i].col(k), b = track_[i].col(k + 1);
  const auto ma = slopes_[i].col(k), mb = slopes_[i].col(k + 1);
  xbar = hermite(a, ma, b, mb, u, h, 0);
  if (rate) *rate = hermite(a, ma, b, mb, u, h, 1);
  return true;
}

Eigen::Vector4d MarkerObjective::weights(int i, const FemModel& model) const {
  Eigen::Vector4d w = embedding_[i].weights;
  if (obs_.marker_offsets.cols() == num_markers() && !obs_.marker_offsets.col(i).isZero()) {
    const auto& G = model.elements()[embedding_[i].tet].G;
    w += G.transpose() * obs_.marker_offsets.col(i);
  }
  return w;
}

Eigen::Vector3d MarkerObjective::simulated(int i, const FemModel& model,
                                           const Eigen::Matrix3Xd& x) const {
  const Eigen::Vector4d w = weights(i, model);
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (int a = 0; a < 4; ++a) p += w[a] * x.col(model.mesh().tets(a, embedding_[i].tet));
  return p;
}

Eigen::Vector3d MarkerObjective::registered(const Eigen::Vector3d& xbar) const {
  // The nominal registration leaves the capture bit for bit as recorded.
  if (obs_.rotation.isZero() && obs_.translation.isZero()) return xbar;
  return R_ * (xbar - centroid_) + centroid_ + obs_.translation;
}

bool MarkerObjective::pair(int i, double t, double offset, const FemModel& model,
                           const Eigen::Matrix3Xd& x, Eigen::Vector3d& simulated_position,
                           Eigen::Vector3d& observed_position, double* presence) const {
  Eigen::Vector3d xbar;
  if (!observed(i, t, offset, xbar, nullptr, presence)) return false;
  simulated_position = simulated(i, model, x);
  observed_position = registered(xbar);
  return true;
}

bool MarkerObjective::marker_pair(int i, double t, const FemModel& model, const Eigen::Matrix3Xd& x,
                                  Eigen::Vector3d& simulated_position,
                                  Eigen::Vector3d& observed_position, double* presence) const {
  return pair(i, t, obs_.clock_offset, model, x, simulated_position, observed_position, presence);
}

bool MarkerObjective::sample_pair(int i, double t, const FemModel& model, const Eigen::Matrix3Xd& x,
                                  Eigen::Vector3d& simulated_position,
                                  Eigen::Vector3d& observed_position) const {
  return pair(i, t, 0, model, x, simulated_position, observed_position);
}

void MarkerObjective::integrand(double t, const FemModel& model, const Eigen::Matrix3Xd& x,
                                double* g) const {
  Eigen::Vector3d xs, xo;
  double c;
  for (int i = 0; i < num_markers(); ++i)
    g[i] = marker_pair(i, t, model, x, xs, xo, &c)
               ? 0.5 * weight_[i] * (c * (xs - xo)).squaredNorm()
               : 0.0;
}

void MarkerObjective::add_gradient(double t, const FemModel& model, const Eigen::Matrix3Xd& x,
                                   double* grad) const {
  Eigen::Vector3d xs, xo;
  double c;
  for (int i = 0; i < num_markers(); ++i) {
    if (!marker_pair(i, t, model, x, xs, xo, &c)) continue;
    const Eigen::Vector3d r = weight_[i] * c * c * (xs - xo);
    const Eigen::Vector4d w = weights(i, model);
    for (int a = 0; a < 4; ++a)
      for (int k = 0; k < 3; ++k) {
        const int d = model.dof(model.mesh().tets(a, embedding_[i].tet), k);
        if (d >= 0) grad[d] += w[a] * r[k];
      }
  }
}

void MarkerObjective::offset_and_registration_columns(int i, const FemModel& model,
                                                      const Eigen::Matrix3Xd& x,
                                                      const Eigen::Vector3d& xbar,
                                                      Eigen::Matrix3Xd& J) const {
  const int nm = num_markers();
  // ∂x*/∂δ = Σₐ xₐ ∇Nₐᵀ, the element's deformation gradient.
  const auto& el = model.elements()[embedding_[i].tet];
  Eigen::Matrix3d F = Eigen::Matrix3d::Zero();
  for (int a = 0; a < 4; ++a) F += x.col(el.nodes[a]) * el.G.col(a).transpose();
  J.middleCols<3>(1 + 3 * i) = F;
  // ∂(R v)/∂ω = −R [v]× J_r, v = x̄ − c; ∂x̄'/∂d = I.
  J.middleCols<3>(1 + 3 * nm) = R_ * skew(xbar - centroid_) * Jr_;
  J.middleCols<3>(4 + 3 * nm) = -Eigen::Matrix3d::Identity();
}

Eigen::Matrix3Xd MarkerObjective::pair_jacobian(int i, double t, const FemModel& model,
                                                const Eigen::Matrix3Xd& x) const {
  Eigen::Matrix3Xd J = Eigen::Matrix3Xd::Zero(3, num_observation_parameters());
  Eigen::Vector3d xbar, rate;
  double c, dc;
  if (!observed(i, t, obs_.clock_offset, xbar, &rate, &c, &dc)) return J;
  J.col(0) = -R_ * rate;  // ∂x̄'/∂τ = R dx̄/dt
  offset_and_registration_columns(i, model, x, xbar, J);
  if (c == 1 && dc == 0) return J;
  // The counted residual c (x* − x̄'): its weight moves with τ too.
  J *= c;
  J.col(0) += dc * (simulated(i, model, x) - registered(xbar));
  return J;
}

Eigen::Matrix3Xd MarkerObjective::sample_jacobian(int i, double t, const FemModel& model,
                                                  const Eigen::Matrix3Xd& x,
                                                  const Eigen::Matrix3Xd& v,
                                                  bool clock_moves) const {
  Eigen::Matrix3Xd J = Eigen::Matrix3Xd::Zero(3, num_observation_parameters());
  Eigen::Vector3d xbar;
  if (!observed(i, t, 0, xbar)) return J;
  // x*(t − τ): ∂/∂τ = −ẋ*, the simulated marker's velocity.
  if (clock_moves) J.col(0) = -simulated(i, model, v);
  offset_and_registration_columns(i, model, x, xbar, J);
  return J;
}

void MarkerObjective::observation_gradient(double t, const FemModel& model,
                                           const Eigen::Matrix3Xd& x, double* out) const {
  Eigen::Map<Eigen::VectorXd> g(out, num_observation_parameters());
  g.setZero();
  Eigen::Vector3d xs, xo;
  double c;
  for (int i = 0; i < num_markers(); ++i) {
    if (!marker_pair(i, t, model, x, xs, xo, &c)) continue;
    g += pair_jacobian(i, t, model, x).transpose() * (weight_[i] * c * (xs - xo));
  }
}

Eigen::VectorXd MarkerObjective::marker_rms(const Eigen::VectorXd& phi) const {
  Eigen::VectorXd rms(num_markers());
  for (int i = 0; i < num_markers(); ++i)
    rms[i] = weighted_time_[i] > 0 ? std::sqrt(2 * phi[i] / weighted_time_[i]) : NAN;
  return rms;
}

}  // namespace kelvin
