#pragma once
/// \file
/// OptiTrack Motive's CSV export: a metadata row (format version, frame rates,
/// length units, rotation type), the Type / Name / ID rows, the property row
/// (Position, Rotation, Mean Marker Error, ...), the axis row (Frame, Time, X, Y, Z,
/// W) and one row per frame. Markers (labelled or a rigid body's) become tracks,
/// rigid bodies poses (quaternion rotations only); empty cells are not seen.
#include <string>

#include "capture/capture.hpp"

namespace kelvin {

Capture read_motive_csv(const std::string& path);

}  // namespace kelvin
