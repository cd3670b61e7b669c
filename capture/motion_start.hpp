#pragma once
/// \file
/// Where a capture's motion begins: the still frames at its start, their noise, the
/// first frame that moved, and for a body released from rest the release time t₀
/// from the first frames of its fall (every point of a body released from rest
/// starts with the same acceleration a, so the displacement grows as ½a(t − t₀)²).
#include <vector>

#include "engine/csv.hpp"

namespace kelvin {

struct MotionStart {
  int still_frames = 0;     // frames [0, still_frames) used for the noise level
  double noise = 0;         // RMS distance of the markers' centroid from its still mean (m)
  double threshold = 0;     // displacement that counts as motion (m)
  int onset = -1;           // first frame displaced more than threshold (−1: none)
  int rest_frames = 0;      // frames [0, rest_frames) are at rest (20 ms or more before onset)
  double release = 0;       // t₀ (s): the ½a(t − t₀)² fit, or the last rest frame's time
  double acceleration = 0;  // a of that fit (m/s²; 0 without one)
  int fall_frames = 0;      // frames the fit used
};

/// The motion start of the centroid of `markers` (indices into tracks.names);
/// frames where any of them is occluded are left out of the centroid.
MotionStart find_motion_start(const MarkerTracks& tracks, const std::vector<int>& markers);

}  // namespace kelvin
