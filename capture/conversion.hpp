#pragma once
/// \file
/// A capture turned into kelvin's inputs: tracks in the model frame (registered by
/// named correspondences), from the start of the motion, and their rest positions;
/// a rigid body's poses as a clamp motion relative to its pose at the start.
#include <optional>
#include <string>
#include <vector>

#include "capture/capture.hpp"
#include "capture/motion_start.hpp"
#include "capture/registration.hpp"

namespace kelvin {

struct ConversionOptions {
  /// Model-frame positions of some markers (`name,x,y,z`): the registration's
  /// correspondences, matched by name to the capture's mean positions at rest. None:
  /// the capture frame is the model frame.
  std::optional<MarkerRest> layout;
  std::vector<std::string> markers;  // the tracks to write (empty: all)
  std::vector<std::string> moving;   // whose centroid finds the motion start (empty: markers)
  enum class Start { kCapture, kRelease, kMotion, kTime } start = Start::kCapture;
  double start_time = 0;            // Start::kTime (s, capture clock)
  double duration = 0;              // s after the start; 0 = to the end
  std::vector<std::string> bodies;  // rigid bodies to write as clamp motions
};

struct Conversion {
  MotionStart motion;  // of the moving markers
  std::optional<Registration> registration;
  double start = 0;          // capture time that becomes t = 0
  MarkerTracks tracks;       // model frame, t from the start
  Eigen::Matrix3Xd rest;     // per written marker: mean at rest, model frame
  std::vector<double> seen;  // per written marker: fraction of frames seen
  std::vector<std::pair<std::string, ClampSamples>> clamps;  // per body
};

/// Converts `capture` (read from `path`, named in messages).
Conversion convert_capture(const Capture& capture, const ConversionOptions& options,
                           const std::string& path);

/// kelvin's CSV formats: tracks `t,a_x,...`, rest positions `name,x,y,z`, and a clamp
/// motion `t,tx,ty,tz,qw,qx,qy,qz`.
std::string tracks_csv(const MarkerTracks& tracks);
std::string rest_csv(const std::vector<std::string>& names, const Eigen::Matrix3Xd& rest);
std::string clamp_csv(const ClampSamples& samples);

}  // namespace kelvin
