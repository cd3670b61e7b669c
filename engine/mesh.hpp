#pragma once
// Tetrahedral meshes: the data structure, built-in generators, file readers and
// validation. Node positions are the rest (material) configuration in metres.
#include <Eigen/Core>
#include <string>
#include <vector>

namespace kelvin {

struct Mesh {
  Eigen::Matrix3Xd nodes;                      // rest positions, one column per node
  Eigen::Matrix<int, 4, Eigen::Dynamic> tets;  // 0-based node indices, one column per tet
  std::vector<int> region;                     // per-tet region label (0 when the source has none)
  std::string source;                          // file path or generator description, for messages
  int reordered = 0;  // tetrahedra read in negative orientation and reordered (orient_tetrahedra)
  int refined = 0;    // levels of uniform refinement applied (refine_uniformly)

  int num_nodes() const { return static_cast<int>(nodes.cols()); }
  int num_tets() const { return static_cast<int>(tets.cols()); }
};

/// Axis-aligned box [lo, hi] split into hexahedral cells of edge about `h`, each
/// cut into 6 tetrahedra (Kuhn split, conforming across cells).
Mesh generate_box(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double h);

/// Circular cylinder of `radius` along `axis` (0=x, 1=y, 2=z) from 0 to `length`,
/// centred on the axis, target element size `h`.
Mesh generate_cylinder(double radius, double length, double h, int axis = 2);

/// The number of tetrahedra generate_box / generate_cylinder would make, so that a
/// caller can refuse a size before allocating it.
double box_tet_count(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double h);
double cylinder_tet_count(double radius, double length, double h);

/// Reads Gmsh .msh (ASCII 4.1 or 2.2; physical tags become regions),
/// TetGen (.node/.ele, given either file; the .ele attribute becomes the region).
/// Throws kelvin::Error naming the file and line on malformed input.
Mesh read_mesh(const std::string& path);
Mesh read_gmsh(const std::string& path);
Mesh read_tetgen(const std::string& path);

/// Swaps two nodes of every tetrahedron listed in negative orientation (as dolfin and
/// other tools write them: a rest mesh has node orderings, not inverted elements) and
/// counts them in mesh.reordered. Degenerate tetrahedra are left for validate_mesh.
void orient_tetrahedra(Mesh& mesh);

/// Throws kelvin::Error naming the first offending element or node: inverted or
/// degenerate tetrahedra (volume below 1e-12 of the mean), node indices out of
/// range, unreferenced nodes, faces shared by more than two tetrahedra.
void validate_mesh(const Mesh& mesh);

/// Signed volume of tet e in the rest configuration.
double tet_volume(const Mesh& mesh, int e);

}  // namespace kelvin
