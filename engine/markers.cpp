#include "engine/markers.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <fmt/format.h>

#include <cmath>
#include <limits>

#include "engine/error.hpp"

namespace kelvin {
namespace {

Eigen::Vector4d barycentric(const Mesh& m, int e, const Eigen::Vector3d& p) {
  const Eigen::Vector3d p0 = m.nodes.col(m.tets(0, e));
  Eigen::Matrix3d A;
  for (int k = 0; k < 3; ++k) A.col(k) = m.nodes.col(m.tets(k + 1, e)) - p0;
  const Eigen::Vector3d l = A.partialPivLu().solve(p - p0);
  return {1 - l.sum(), l[0], l[1], l[2]};
}

/// Closest point to p on triangle abc (Ericson, Real-Time Collision Detection, 5.1.5).
Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                    const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + d1 / (d1 - d3) * ab;
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
    return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
  const double denom = 1 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

}  // namespace

std::vector<MarkerEmbedding> embed_markers(const Mesh& mesh, const std::vector<std::string>& names,
                                           const Eigen::Matrix3Xd& rest, double tolerance) {
  std::vector<MarkerEmbedding> out;
  const int ne = mesh.num_tets();
  for (int i = 0; i < static_cast<int>(names.size()); ++i) {
    const Eigen::Vector3d p = rest.col(i);
    MarkerEmbedding best{names[i], -1, Eigen::Vector4d::Zero(), std::numeric_limits<double>::infinity()};
    Eigen::Vector3d best_point = p;
    for (int e = 0; e < ne && best.outside_distance > 0; ++e) {
      const Eigen::Vector4d w = barycentric(mesh, e, p);
      if (w.minCoeff() >= -1e-10) {
        best.tet = e;
        best.weights = w.cwiseMax(0.0) / w.cwiseMax(0.0).sum();
        best.outside_distance = 0;
        break;
      }
      // Outside this tet: its closest point is on one of its faces.
      for (int skip = 0; skip < 4; ++skip) {
        int f[3];
        for (int k = 0, j = 0; k < 4; ++k)
          if (k != skip) f[j++] = mesh.tets(k, e);
        const Eigen::Vector3d q = closest_on_triangle(p, mesh.nodes.col(f[0]), mesh.nodes.col(f[1]),
                                                      mesh.nodes.col(f[2]));
        const double d = (q - p).norm();
        if (d < best.outside_distance) {
          best.outside_distance = d;
          best.tet = e;
          best_point = q;
        }
      }
    }
    if (best.outside_distance > 0) {
      if (best.outside_distance > tolerance)
        throw Error(fmt::format(
            "marker '{}' at ({:.6g}, {:.6g}, {:.6g}) is {:.3g} mm outside the mesh (tolerance "
            "{:.3g} mm)",
            names[i], p[0], p[1], p[2], 1e3 * best.outside_distance, 1e3 * tolerance));
      const Eigen::Vector4d w = barycentric(mesh, best.tet, best_point).cwiseMax(0.0);
      best.weights = w / w.sum();
    }
    out.push_back(best);
  }
  return out;
}

Eigen::Matrix3Xd marker_positions(const Mesh& mesh, const std::vector<MarkerEmbedding>& markers,
                                  const Eigen::Matrix3Xd& x) {
  Eigen::Matrix3Xd out(3, markers.size());
  for (size_t i = 0; i < markers.size(); ++i) {
    out.col(i).setZero();
    for (int a = 0; a < 4; ++a) out.col(i) += markers[i].weights[a] * x.col(mesh.tets(a, markers[i].tet));
  }
  return out;
}

}  // namespace kelvin
