#include "capture/motion_start.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <optional>

#include "base/error.hpp"

namespace kelvin {
namespace {

/// Still window: up to 0.5 s, ending 0.1 s before the centroid first moves 1 mm.
constexpr double kStillWindow = 0.5, kStillMargin = 0.1, kGrossMove = 1e-3;
/// Motion is a displacement above this many noise levels (the RMS of a 3D distance
/// under Gaussian noise; 8 of them are a 1-in-10¹⁰ event per frame).
constexpr double kNoiseMultiple = 8;
/// Rest frames end this long before the onset.
constexpr double kRestMargin = 0.02;
/// The fall fit uses the frames from the last at rest to two after the onset (at
/// 100 Hz the first ~25 ms of a beam's release, before its bending slows the tip)
/// whose displacement is above this many noise levels (below, noise biases √d).
constexpr double kFallNoiseMultiple = 2;
constexpr int kFallFramesAfterOnset = 2;

std::optional<Eigen::Vector3d> centroid(const MarkerTracks& t, const std::vector<int>& m, long k) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int i : m) {
    const Eigen::Vector3d p = t.xyz.col(k).segment<3>(3 * i);
    if (p.hasNaN()) return std::nullopt;
    c += p;
  }
  return c / static_cast<double>(m.size());
}

}  // namespace

MotionStart find_motion_start(const MarkerTracks& t, const std::vector<int>& markers) {
  if (markers.empty()) throw Error("find_motion_start: no markers");
  const long n = static_cast<long>(t.times.size());
  std::vector<std::optional<Eigen::Vector3d>> c(n);
  for (long k = 0; k < n; ++k) c[k] = centroid(t, markers, k);
  long first = 0;
  while (first < n && !c[first]) ++first;
  if (first == n) throw Error("the chosen markers are never all seen in one frame");

  MotionStart s;
  long gross = n;
  for (long k = first; k < n; ++k)
    if (c[k] && (*c[k] - *c[first]).norm() > kGrossMove) {
      gross = k;
      break;
    }
  const double window_end = std::min(t.times[first] + kStillWindow,
                                     gross < n ? t.times[gross] - kStillMargin : t.times[n - 1]);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  int count = 0;
  for (long k = first; k < n && t.times[k] <= window_end; ++k)
    if (c[k]) mean += *c[k], ++count;
  if (count < 2)
    throw Error(
        fmt::format("the capture moves within {:g} s of its start: no still frames to "
                    "measure the noise on",
                    kStillMargin));
  mean /= count;
  double sum = 0;
  long last_still = first;
  for (long k = first; k < n && t.times[k] <= window_end; ++k)
    if (c[k]) sum += (*c[k] - mean).squaredNorm(), last_still = k;
  s.still_frames = static_cast<int>(last_still + 1);
  s.noise = std::sqrt(sum / count);
  s.threshold = kNoiseMultiple * s.noise;

  std::vector<double> d(n, NAN);
  for (long k = 0; k < n; ++k)
    if (c[k]) d[k] = (*c[k] - mean).norm();
  for (long k = s.still_frames; k < n; ++k)
    if (d[k] > s.threshold) {
      s.onset = static_cast<int>(k);
      break;
    }
  if (s.onset < 0) {
    s.rest_frames = static_cast<int>(n);
    return s;
  }
  long rest = 0;
  while (rest < n && t.times[rest] <= t.times[s.onset] - kRestMargin) ++rest;
  s.rest_frames = static_cast<int>(std::max(rest, 1L));
  s.release = t.times[s.rest_frames - 1];

  // sqrt(d) = sqrt(a/2) (t − t₀) on the first frames of the fall.
  std::vector<double> xs, ys;
  for (long k = s.rest_frames - 1; k <= std::min<long>(s.onset + kFallFramesAfterOnset, n - 1); ++k)
    if (d[k] > kFallNoiseMultiple * s.noise) {
      xs.push_back(t.times[k]);
      ys.push_back(std::sqrt(d[k]));
    }
  if (xs.size() >= 2) {
    double xm = 0, ym = 0;
    for (size_t k = 0; k < xs.size(); ++k) xm += xs[k], ym += ys[k];
    xm /= xs.size();
    ym /= ys.size();
    double sxy = 0, sxx = 0;
    for (size_t k = 0; k < xs.size(); ++k)
      sxy += (xs[k] - xm) * (ys[k] - ym), sxx += (xs[k] - xm) * (xs[k] - xm);
    const double slope = sxx > 0 ? sxy / sxx : 0;
    const double t0 = slope > 0 ? xm - ym / slope : NAN;
    // Accepted only where it falls between the last rest frame and the onset.
    if (std::isfinite(t0) && t0 >= t.times[s.rest_frames - 1] && t0 <= t.times[s.onset]) {
      s.release = t0;
      s.acceleration = 2 * slope * slope;
      s.fall_frames = static_cast<int>(xs.size());
    }
  }
  return s;
}

}  // namespace kelvin
