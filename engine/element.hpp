#pragma once
/// \file
/// Linear tetrahedron kinematics. With shape-function gradients G = [∇N₀ … ∇N₃]
/// (3×4, constant per element) and nodal positions x_e (3×4):
///   F = x_e G,   Ḟ = v_e G,   resisting force on the element's nodes = V P G,
/// so the element stiffness block (a,b) is V Σ_jl ∇N_a,j dP/dF(i+3j, k+3l) ∇N_b,l.
#include <Eigen/Core>

#include "engine/mesh.hpp"
#include "materials/material.hpp"

namespace kelvin {

struct TetElement {
  int nodes[4];
  double volume;                  // rest volume
  Eigen::Matrix<double, 3, 4> G;  // columns: ∇N_a in the rest configuration
};

/// Precomputes rest volume and shape gradients; throws kelvin::Error naming the
/// element when it is inverted or degenerate.
TetElement make_tet_element(const Mesh& mesh, int e);

/// 12×12 element matrix V Gᵀ A G for a 9×9 tangent A = dP/dF or dP/dḞ (local
/// dof order 3a + i). The matrix is accumulated (+=) into `out` times `scale`.
void accumulate_element_matrix(const TetElement& el, const Mat9& A, double scale,
                               Eigen::Matrix<double, 12, 12>& out);

/// out = (V Gᵀ A G)ᵀ λ_e as a 3×4 nodal field, without forming the 12×12 matrix:
/// with Λ = λ_e Gᵀ, out = V W G where vec(W) = Aᵀ vec(Λ).
void element_transpose_product(const TetElement& el, const Mat9& A,
                               const Eigen::Matrix<double, 3, 4>& lambda,
                               Eigen::Matrix<double, 3, 4>& out);

}  // namespace kelvin
