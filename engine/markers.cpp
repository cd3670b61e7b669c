#include "engine/markers.hpp"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <limits>
#include <vector>

#include "base/error.hpp"

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

struct Box {
  Eigen::Vector3d lo, hi;
  /// Distance from p to the box (0 inside): a lower bound on the distance to the tet.
  double distance(const Eigen::Vector3d& p) const {
    return (lo - p).cwiseMax(p - hi).cwiseMax(0.0).norm();
  }
};

std::vector<Box> tet_boxes(const Mesh& m) {
  std::vector<Box> boxes(m.num_tets());
  for (int e = 0; e < m.num_tets(); ++e) {
    Box& b = boxes[e];
    b.lo = b.hi = m.nodes.col(m.tets(0, e));
    for (int k = 1; k < 4; ++k) {
      b.lo = b.lo.cwiseMin(m.nodes.col(m.tets(k, e)));
      b.hi = b.hi.cwiseMax(m.nodes.col(m.tets(k, e)));
    }
  }
  return boxes;
}

/// The tet containing p, or -1. Tolerant by 1e-10 in the weights so that points on
/// shared faces (and the mesh surface) count as inside.
int containing_tet(const Mesh& m, const std::vector<Box>& boxes, const Eigen::Vector3d& p,
                   Eigen::Vector4d& weights) {
  for (int e = 0; e < m.num_tets(); ++e) {
    const double slack = 1e-10 * (boxes[e].hi - boxes[e].lo).norm();
    if (boxes[e].distance(p) > slack) continue;
    const Eigen::Vector4d w = barycentric(m, e, p);
    if (w.minCoeff() >= -1e-10) {
      weights = w.cwiseMax(0.0) / w.cwiseMax(0.0).sum();
      return e;
    }
  }
  return -1;
}

/// Nearest point of the mesh to an outside point p: the nearest over all tets of
/// the nearest point on their faces; boxes skip tets that cannot be closer.
int nearest_tet(const Mesh& m, const std::vector<Box>& boxes, const Eigen::Vector3d& p,
                Eigen::Vector3d& nearest, double& distance) {
  int best = -1;
  distance = std::numeric_limits<double>::infinity();
  for (int e = 0; e < m.num_tets(); ++e) {
    if (boxes[e].distance(p) >= distance) continue;
    for (int skip = 0; skip < 4; ++skip) {
      int f[3];
      for (int k = 0, j = 0; k < 4; ++k)
        if (k != skip) f[j++] = m.tets(k, e);
      const Eigen::Vector3d q =
          closest_on_triangle(p, m.nodes.col(f[0]), m.nodes.col(f[1]), m.nodes.col(f[2]));
      const double d = (q - p).norm();
      if (d < distance) {
        distance = d;
        best = e;
        nearest = q;
      }
    }
  }
  return best;
}

}  // namespace

std::vector<MarkerEmbedding> embed_markers(const Mesh& mesh, const std::vector<std::string>& names,
                                           const Eigen::Matrix3Xd& rest, double tolerance) {
  if (static_cast<Eigen::Index>(names.size()) != rest.cols())
    throw Error(fmt::format("embed_markers: {} marker names but {} rest positions", names.size(),
                            rest.cols()));
  if (mesh.num_tets() == 0) throw Error(mesh.source + ": cannot embed markers in an empty mesh");
  const std::vector<Box> boxes = tet_boxes(mesh);
  std::vector<MarkerEmbedding> out;
  for (size_t i = 0; i < names.size(); ++i) {
    const Eigen::Vector3d p = rest.col(i);
    if (!p.allFinite())
      throw Error(fmt::format("marker '{}' has a non-finite rest position", names[i]));
    MarkerEmbedding mk;
    mk.name = names[i];
    mk.tet = containing_tet(mesh, boxes, p, mk.weights);
    if (mk.tet < 0) {
      Eigen::Vector3d q;
      mk.tet = nearest_tet(mesh, boxes, p, q, mk.outside_distance);
      if (mk.outside_distance > tolerance)
        throw Error(fmt::format(
            "marker '{}' at ({:.6g}, {:.6g}, {:.6g}) is {:.3g} mm outside the mesh (tolerance "
            "{:.3g} mm)",
            names[i], p[0], p[1], p[2], 1e3 * mk.outside_distance, 1e3 * tolerance));
      // q lies on a face of the tet, so its weights are in [0, 1] up to rounding.
      const Eigen::Vector4d w = barycentric(mesh, mk.tet, q).cwiseMax(0.0);
      mk.weights = w / w.sum();
    }
    out.push_back(mk);
  }
  return out;
}

Eigen::Matrix3Xd marker_positions(const Mesh& mesh, const std::vector<MarkerEmbedding>& markers,
                                  const Eigen::Matrix3Xd& x) {
  if (x.cols() != mesh.num_nodes())
    throw Error(fmt::format("marker_positions: {} nodal positions for a mesh of {} nodes", x.cols(),
                            mesh.num_nodes()));
  Eigen::Matrix3Xd out(3, markers.size());
  for (size_t i = 0; i < markers.size(); ++i) {
    out.col(i).setZero();
    for (int a = 0; a < 4; ++a)
      out.col(i) += markers[i].weights[a] * x.col(mesh.tets(a, markers[i].tet));
  }
  return out;
}

}  // namespace kelvin
