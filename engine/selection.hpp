#pragma once
// Node selections used by clamps (and later loads): a plane, a box, or explicit ids.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "engine/mesh.hpp"

namespace kelvin {

struct NodeSelection {
  enum class Kind { Plane, Box, Ids } kind = Kind::Plane;
  int axis = 2;           // Plane: 0=x, 1=y, 2=z
  double at = 0;          // Plane: coordinate of the plane
  double tolerance = -1;  // Plane: |X_axis - at| <= tolerance; <0: 1e-6 × mesh diameter
  Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();  // Box
  std::vector<int> ids;  // Ids: 0-based node indices
};

/// Sorted, unique node indices. Does not throw on an empty result: callers decide
/// (a clamp with no node is an input error that names the clamp).
std::vector<int> select_nodes(const Mesh& mesh, const NodeSelection& sel);

}  // namespace kelvin
