#include "engine/element.hpp"

#include <fmt/format.h>

#include <Eigen/LU>

#include "base/error.hpp"

namespace kelvin {

TetElement make_tet_element(const Mesh& mesh, int e) {
  TetElement el;
  Eigen::Matrix3d Dm;
  for (int a = 0; a < 4; ++a) el.nodes[a] = mesh.tets(a, e);
  for (int c = 0; c < 3; ++c)
    Dm.col(c) = mesh.nodes.col(el.nodes[c + 1]) - mesh.nodes.col(el.nodes[0]);
  const double det = Dm.determinant();
  el.volume = det / 6.0;
  const double scale = Dm.colwise().norm().maxCoeff();
  if (!(det > 1e-12 * scale * scale * scale))
    throw Error(fmt::format("mesh {}: element {} (nodes {} {} {} {}) is {} (volume {:.3g} m³)",
                            mesh.source, e, el.nodes[0], el.nodes[1], el.nodes[2], el.nodes[3],
                            det < 0 ? "inverted" : "degenerate", el.volume));
  // Rows of Dm⁻¹ are the gradients of N₁..N₃; N₀ = 1 − N₁ − N₂ − N₃.
  const Eigen::Matrix3d Dinv = Dm.inverse();
  for (int c = 0; c < 3; ++c) el.G.col(c + 1) = Dinv.row(c).transpose();
  el.G.col(0) = -el.G.rightCols<3>().rowwise().sum();
  return el;
}

void accumulate_element_matrix(const TetElement& el, const Mat9& A, double scale,
                               Eigen::Matrix<double, 12, 12>& out) {
  // T(:, 3b+k) = Σ_l A(:, k+3l) ∇N_b,l ; out(3a+i, 3b+k) += s Σ_j ∇N_a,j T(i+3j, 3b+k)
  Eigen::Matrix<double, 9, 12> T;
  for (int b = 0; b < 4; ++b)
    for (int k = 0; k < 3; ++k)
      T.col(3 * b + k) =
          A.col(k) * el.G(0, b) + A.col(k + 3) * el.G(1, b) + A.col(k + 6) * el.G(2, b);
  const double s = scale * el.volume;
  for (int a = 0; a < 4; ++a)
    for (int i = 0; i < 3; ++i)
      out.row(3 * a + i) +=
          s * (el.G(0, a) * T.row(i) + el.G(1, a) * T.row(i + 3) + el.G(2, a) * T.row(i + 6));
}

void element_transpose_product(const TetElement& el, const Mat9& A,
                               const Eigen::Matrix<double, 3, 4>& lambda,
                               Eigen::Matrix<double, 3, 4>& out) {
  const Mat3 L = lambda * el.G.transpose();
  const Eigen::Matrix<double, 9, 1> w = A.transpose() * L.reshaped();
  out = el.volume * w.reshaped(3, 3) * el.G;
}

}  // namespace kelvin
