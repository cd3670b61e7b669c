#pragma once
// Markers embedded in the mesh with barycentric weights in one tetrahedron.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "engine/mesh.hpp"

namespace kelvin {

struct MarkerEmbedding {
  std::string name;
  int tet = -1;
  Eigen::Vector4d weights = Eigen::Vector4d::Zero();  // barycentric, sum to 1
  double outside_distance = 0;  // distance from the rest position to the mesh (0 inside)
};

/// Embeds each marker in the tetrahedron containing it; a marker outside the mesh
/// is projected to the nearest point of the nearest tetrahedron. Throws
/// kelvin::Error naming the marker when it is farther than `tolerance` (m) outside.
std::vector<MarkerEmbedding> embed_markers(const Mesh& mesh, const std::vector<std::string>& names,
                                           const Eigen::Matrix3Xd& rest, double tolerance);

/// Marker positions for a full nodal position field x (3 × nodes).
Eigen::Matrix3Xd marker_positions(const Mesh& mesh, const std::vector<MarkerEmbedding>& markers,
                                  const Eigen::Matrix3Xd& x);

}  // namespace kelvin
