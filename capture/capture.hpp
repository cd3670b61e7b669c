#pragma once
/// \file
/// A motion capture as read from a capture system's file: labelled marker tracks
/// (metres, seconds from the first frame) and, where the format has them, rigid
/// bodies (a pose per frame).
#include <Eigen/Core>
#include <string>
#include <vector>

#include "engine/csv.hpp"

namespace kelvin {

struct RigidBodyTrack {
  std::string name;
  Eigen::MatrixXd pose;  // 7 × frames: translation (m), quaternion w, x, y, z; NaN = not seen
};

struct Capture {
  MarkerTracks markers;  // names as labelled, times from 0, NaN = occluded
  std::vector<RigidBodyTrack> bodies;
  double rate = 0;     // frames per second
  std::string format;  // e.g. "C3D (Intel, float)", "Motive CSV 1.23"
  std::string units;   // the file's length unit, converted to metres on reading
};

/// Reads a C3D or a Motive CSV file, chosen by its content (C3D's header key).
Capture read_capture(const std::string& path);

/// A marker label as a column name of kelvin's track CSV: characters other than
/// letters, digits, '-', '.' and ':' become '_' ("Tip - 1" → "Tip_-_1").
std::string track_name(const std::string& label);

}  // namespace kelvin
