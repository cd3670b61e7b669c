#pragma once
/// \file
/// Files of a fitted body-force field (engine/body_force.hpp): what a fit or the
/// diagnosis writes instead of putting the field into fitted.yaml, since it explains
/// one motion rather than describing the specimen.
#include <string>
#include <vector>

#include "engine/fem_model.hpp"

namespace kelvin {

/// OUTDIR/<base>.csv (one row per knot and element: t, element, fx, fy, fz as the
/// force density ρ a in N/m³) and the VTU series <base>.pvd on the rest mesh (one
/// frame per knot; cell data force_x, force_y, force_z, force_magnitude). Returns
/// the names written (none when the model's field is inactive).
std::vector<std::string> write_body_force(const FemModel& model, const std::string& outdir,
                                          const std::string& base = "body-force");

}  // namespace kelvin
