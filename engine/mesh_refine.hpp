#pragma once
/// \file
/// Uniform refinement of a tetrahedral mesh, for mesh-convergence checks on any mesh
/// (a file's as well as a generated one) and the diagnosis's discretisation candidate.
#include "engine/mesh.hpp"

namespace kelvin {

/// Each tetrahedron split into eight at its edge midpoints (Bey's red refinement:
/// four corner tetrahedra and the inner octahedron cut along its shortest diagonal),
/// `levels` times. Conforming (a shared edge gets one midpoint), every child
/// positively oriented and in its parent's region; the first num_nodes() nodes are
/// the original ones, in order.
Mesh refine_uniformly(const Mesh& mesh, int levels = 1);

}  // namespace kelvin
