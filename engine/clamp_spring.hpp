#pragma once
/// \file
/// A compliant clamp: instead of prescribing its nodes, the clamp pulls them toward
/// where its motion carries them, through a Kelvin–Voigt pad of stiffness 1/c per
/// area (compliance c, m³/N: a Robin condition) and retardation time τ (s), over the
/// boundary faces whose three nodes it holds. Consistent over each triangle, the force
/// on node a is Σ_b S_ab [(x_b − x̂_b) + τ (v_b − v̂_b)]/c with S_ab = A (1 + δ_ab)/12.
/// As c → 0 the nodes follow the motion: the rigid clamp is the limit, so a fit of c
/// from a tiny value is a nested extension. The dashpot scales with the spring so
/// that a stiff pad stays overdamped (real eigenvalues, which every BDF order damps);
/// an undamped stiff pad rings at kHz and the integrator must follow it.
#include <Eigen/Core>
#include <array>
#include <vector>

#include "engine/mesh.hpp"

namespace kelvin {

struct ClampFace {
  int clamp = 0;               // index into FemModel::clamps()
  int element = 0;             // the tetrahedron the face bounds
  std::array<int, 3> nodes{};  // mesh nodes
  std::array<int, 3> local{};  // their places among the element's four nodes
  double area = 0;
};

/// The boundary faces of `mesh` whose three nodes are all in `nodes`, tagged `clamp`.
std::vector<ClampFace> clamp_faces(const Mesh& mesh, const std::vector<int>& nodes, int clamp);

/// S_ab of a face (a, b ∈ 0…2): A/6 on the diagonal, A/12 off it.
inline double face_weight(const ClampFace& f, int a, int b) {
  return f.area / 12 * (a == b ? 2 : 1);
}

/// Σ_b S_ab u(b) at node a of face f: the pads' weights applied to a field given per
/// face node (positions, gaps, an adjoint).
template <class Field>
Eigen::Vector3d face_product(const ClampFace& f, int a, Field u) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int b = 0; b < 3; ++b) sum += face_weight(f, a, b) * u(b);
  return sum;
}

}  // namespace kelvin
