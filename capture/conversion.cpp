#include "capture/conversion.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "base/error.hpp"

namespace kelvin {
namespace {

int index_of(const std::vector<std::string>& names, const std::string& name,
             const std::string& path, const char* what) {
  const auto it = std::find(names.begin(), names.end(), name);
  if (it == names.end()) {
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
    throw Error(
        fmt::format("{}: {} '{}' is not in the capture (markers: {})", path, what, name, list));
  }
  return static_cast<int>(it - names.begin());
}

/// Mean position of marker i over frames [0, frames) where it was seen.
Eigen::Vector3d rest_mean(const MarkerTracks& t, int i, int frames, const std::string& path) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  int n = 0;
  for (int k = 0; k < frames; ++k)
    if (const Eigen::Vector3d p = t.xyz.col(k).segment<3>(3 * i); !p.hasNaN()) sum += p, ++n;
  if (n == 0)
    throw Error(fmt::format("{}: marker '{}' is not seen in the {} frames at rest", path,
                            t.names[i], frames));
  return sum / n;
}

}  // namespace

Conversion convert_capture(const Capture& capture, const ConversionOptions& o,
                           const std::string& path) {
  const MarkerTracks& in = capture.markers;
  const long frames = static_cast<long>(in.times.size());
  std::vector<int> out;
  if (o.markers.empty())
    for (int i = 0; i < static_cast<int>(in.names.size()); ++i) out.push_back(i);
  for (const auto& m : o.markers) out.push_back(index_of(in.names, m, path, "marker"));
  if (out.empty()) throw Error(fmt::format("{}: the capture has no markers", path));
  std::vector<int> moving;
  for (const auto& m : o.moving) moving.push_back(index_of(in.names, m, path, "moving marker"));
  if (moving.empty()) moving = out;

  Conversion c;
  using Start = ConversionOptions::Start;
  // A start that is given needs no motion detection: a capture that moves at once
  // then has its first frame as the rest.
  try {
    c.motion = find_motion_start(in, moving);
  } catch (const Error&) {
    if (o.start == Start::kRelease || o.start == Start::kMotion) throw;
    c.motion = MotionStart{};
    c.motion.still_frames = 1;
  }
  if ((o.start == Start::kRelease || o.start == Start::kMotion) && c.motion.onset < 0)
    throw Error(fmt::format(
        "{}: the markers never move more than {:.3g} mm (8× their noise at rest, {:.3g} mm): no "
        "motion to start from; give a start time instead",
        path, 1e3 * c.motion.threshold, 1e3 * c.motion.noise));
  if (o.start == Start::kRelease && c.motion.fall_frames == 0)
    throw Error(fmt::format(
        "{}: the motion at t = {:.4f} s does not start as a release from rest (no ½at² growth "
        "of the displacement in the frames around it); use the motion's onset or a start time",
        path, in.times[c.motion.onset]));
  switch (o.start) {
    case Start::kCapture:
      c.start = 0;
      break;
    case Start::kRelease:
    case Start::kMotion:
      c.start = c.motion.release;
      break;
    case Start::kTime:
      if (!(o.start_time >= 0) || o.start_time > in.times.back())
        throw Error(fmt::format("{}: start time {:g} s is outside the capture (0 … {:g} s)", path,
                                o.start_time, in.times.back()));
      c.start = o.start_time;
      break;
  }
  // Rest: the still frames before the motion (the frames at the start when it never
  // moves or the start is given).
  const int rest_frames = o.start == Start::kTime || o.start == Start::kCapture
                              ? std::max(1, c.motion.still_frames)
                              : c.motion.rest_frames;

  if (o.layout) {
    std::vector<std::string> names;
    std::vector<Eigen::Vector3d> from, to;
    for (size_t j = 0; j < o.layout->names.size(); ++j) {
      const std::string& name = o.layout->names[j];
      const auto it = std::find(in.names.begin(), in.names.end(), name);
      if (it == in.names.end())
        throw Error(fmt::format("{}: layout marker '{}' is not in the capture", path, name));
      names.push_back(name);
      from.push_back(rest_mean(in, static_cast<int>(it - in.names.begin()), rest_frames, path));
      to.push_back(o.layout->positions.col(static_cast<long>(j)));
    }
    Eigen::Matrix3Xd A(3, from.size()), B(3, to.size());
    for (size_t j = 0; j < from.size(); ++j) A.col(j) = from[j], B.col(j) = to[j];
    c.registration = fit_registration(A, B, names);
  }
  const auto to_model = [&](const Eigen::Vector3d& x) {
    return c.registration ? c.registration->apply(x) : x;
  };

  // Frames from the start; a release gets a first row at t = 0 holding the rest
  // positions (the body is at rest until t₀, which falls between frames).
  const bool release_row = o.start == Start::kRelease || o.start == Start::kMotion;
  const double end = o.duration > 0 ? c.start + o.duration : HUGE_VAL;
  std::vector<long> keep;
  for (long k = 0; k < frames; ++k)
    if ((release_row ? in.times[k] > c.start : in.times[k] >= c.start - 1e-9) &&
        in.times[k] <= end + 1e-9)
      keep.push_back(k);
  const int nm = static_cast<int>(out.size());
  c.rest.resize(3, nm);
  for (int i = 0; i < nm; ++i) {
    c.tracks.names.push_back(in.names[out[i]]);
    c.rest.col(i) = to_model(rest_mean(in, out[i], rest_frames, path));
  }
  const long rows = static_cast<long>(keep.size()) + (release_row ? 1 : 0);
  c.tracks.xyz.setConstant(3 * nm, rows, std::numeric_limits<double>::quiet_NaN());
  long r = 0;
  if (release_row) {
    c.tracks.times.push_back(0);
    c.tracks.xyz.col(0) = c.rest.reshaped();
    r = 1;
  }
  c.seen.assign(nm, 0);
  for (long k : keep) {
    c.tracks.times.push_back(in.times[k] - c.start);
    for (int i = 0; i < nm; ++i)
      if (const Eigen::Vector3d p = in.xyz.col(k).segment<3>(3 * out[i]); !p.hasNaN()) {
        c.tracks.xyz.col(r).segment<3>(3 * i) = to_model(p);
        c.seen[i] += 1.0 / static_cast<double>(keep.size());
      }
    ++r;
  }

  // Rigid bodies: the motion relative to the pose at the start, in the model frame.
  for (const auto& name : o.bodies) {
    const auto it = std::find_if(capture.bodies.begin(), capture.bodies.end(),
                                 [&](const RigidBodyTrack& b) { return b.name == name; });
    if (it == capture.bodies.end())
      throw Error(fmt::format("{}: rigid body '{}' is not in the capture", path, name));
    const Eigen::Matrix3d Rr = c.registration ? c.registration->R : Eigen::Matrix3d::Identity();
    const Eigen::Vector3d tr = c.registration ? c.registration->t : Eigen::Vector3d::Zero();
    ClampSamples s;
    std::optional<Eigen::Isometry3d> base;
    for (long k = 0; k < frames; ++k) {
      if (in.times[k] < c.start - 1e-9 || in.times[k] > end + 1e-9) continue;
      const auto pose = it->pose.col(k);
      if (pose.hasNaN()) continue;  // a clamp motion is interpolated over gaps
      Eigen::Isometry3d P = Eigen::Isometry3d::Identity();
      P.linear() =
          Rr *
          Eigen::Quaterniond(pose[3], pose[4], pose[5], pose[6]).normalized().toRotationMatrix();
      P.translation() = Rr * pose.head<3>() + tr;
      if (!base) base = P;
      const Eigen::Isometry3d M = P * base->inverse();
      const Eigen::Quaterniond q(M.linear());
      s.t.push_back(in.times[k] - c.start);
      s.translation.push_back(M.translation());
      s.quaternion_wxyz.push_back(Eigen::Vector4d(q.w(), q.x(), q.y(), q.z()));
    }
    if (s.t.size() < 2)
      throw Error(fmt::format("{}: rigid body '{}' is seen in fewer than 2 frames after the start",
                              path, name));
    // The clamp's motion must cover t = 0: the first pose is the rest pose.
    s.t.front() = std::min(s.t.front(), 0.0);
    c.clamps.push_back({name, std::move(s)});
  }
  return c;
}

std::string tracks_csv(const MarkerTracks& t) {
  std::string s = "t";
  for (const auto& n : t.names) s += fmt::format(",{0}_x,{0}_y,{0}_z", n);
  s += "\n";
  for (long k = 0; k < t.xyz.cols(); ++k) {
    s += fmt::format("{:.6f}", t.times[static_cast<size_t>(k)]);
    for (long r = 0; r < t.xyz.rows(); ++r)
      s += std::isnan(t.xyz(r, k)) ? std::string(",") : fmt::format(",{:.7f}", t.xyz(r, k));
    s += "\n";
  }
  return s;
}

std::string rest_csv(const std::vector<std::string>& names, const Eigen::Matrix3Xd& rest) {
  std::string s = "name,x,y,z\n";
  for (size_t i = 0; i < names.size(); ++i)
    s += fmt::format("{},{:.7f},{:.7f},{:.7f}\n", names[i], rest(0, i), rest(1, i), rest(2, i));
  return s;
}

std::string clamp_csv(const ClampSamples& c) {
  std::string s = "t,tx,ty,tz,qw,qx,qy,qz\n";
  for (size_t k = 0; k < c.t.size(); ++k) {
    const auto& p = c.translation[k];
    const auto& q = c.quaternion_wxyz[k];
    s += fmt::format("{:.6f},{:.7f},{:.7f},{:.7f},{:.9f},{:.9f},{:.9f},{:.9f}\n", c.t[k], p.x(),
                     p.y(), p.z(), q[0], q[1], q[2], q[3]);
  }
  return s;
}

}  // namespace kelvin
