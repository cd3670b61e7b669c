#pragma once
/// \file
/// The point section of a C3D file (c3d.org's format): the header, the parameter
/// section's POINT and TRIAL groups, and the 3D point data in Intel, DEC (VAX) or
/// MIPS byte order, integer (scaled) or floating point. Analog data are skipped.
/// A point whose residual word is negative is occluded.
#include <string>

#include "capture/capture.hpp"

namespace kelvin {

Capture read_c3d(const std::string& path);

}  // namespace kelvin
