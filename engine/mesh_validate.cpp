#include <Eigen/Geometry>
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>

#include "engine/error.hpp"
#include "engine/mesh.hpp"

namespace kelvin {

double tet_volume(const Mesh& m, int e) {
  const Eigen::Vector3d a = m.nodes.col(m.tets(0, e));
  return (m.nodes.col(m.tets(1, e)) - a)
             .cross(m.nodes.col(m.tets(2, e)) - a)
             .dot(m.nodes.col(m.tets(3, e)) - a) /
         6.0;
}

void validate_mesh(const Mesh& m) {
  const int nn = m.num_nodes(), ne = m.num_tets();
  auto where = [&](int e) {
    return fmt::format("{}: tetrahedron {} (nodes {} {} {} {}, 0-based)", m.source, e, m.tets(0, e),
                       m.tets(1, e), m.tets(2, e), m.tets(3, e));
  };
  if (ne == 0) throw Error(m.source + ": the mesh has no tetrahedron");
  if (!m.region.empty() && static_cast<int>(m.region.size()) != ne)
    throw Error(m.source + ": region labels do not match the number of tetrahedra");
  for (int a = 0; a < nn; ++a)
    if (!m.nodes.col(a).allFinite())
      throw Error(fmt::format("{}: node {} has a non-finite coordinate", m.source, a));
  for (int e = 0; e < ne; ++e)
    for (int k = 0; k < 4; ++k)
      if (m.tets(k, e) < 0 || m.tets(k, e) >= nn)
        throw Error(fmt::format("{} refers to node {}, but the mesh has {} nodes", where(e),
                                m.tets(k, e), nn));
  double mean = 0;
  for (int e = 0; e < ne; ++e) mean += std::abs(tet_volume(m, e));
  mean /= ne;
  for (int e = 0; e < ne; ++e) {
    const double v = tet_volume(m, e);
    if (v < 0 && std::abs(v) > 1e-12 * mean)
      throw Error(fmt::format("{} is inverted (volume {:.4g} m³ < 0): its node order must be "
                              "positively oriented",
                              where(e), v));
    if (std::abs(v) <= 1e-12 * mean)
      throw Error(fmt::format("{} is degenerate (volume {:.4g} m³, below 1e-12 of the mean {:.4g})",
                              where(e), v, mean));
  }
  std::vector<char> used(nn, 0);
  for (int e = 0; e < ne; ++e)
    for (int k = 0; k < 4; ++k) used[m.tets(k, e)] = 1;
  for (int a = 0; a < nn; ++a)
    if (!used[a])
      throw Error(fmt::format("{}: node {} (0-based) belongs to no tetrahedron", m.source, a));
  // A triangle shared by three or more tets means overlapping or non-manifold input.
  std::map<std::array<int, 3>, std::pair<int, int>> faces;  // face → (count, first tet)
  for (int e = 0; e < ne; ++e)
    for (int skip = 0; skip < 4; ++skip) {
      std::array<int, 3> f;
      for (int k = 0, j = 0; k < 4; ++k)
        if (k != skip) f[j++] = m.tets(k, e);
      std::sort(f.begin(), f.end());
      auto& [count, first] = faces.try_emplace(f, 0, e).first->second;
      if (++count > 2)
        throw Error(fmt::format("{}: the face ({} {} {}) is shared by three or more tetrahedra "
                                "({}, …, {}): the mesh is not manifold",
                                m.source, f[0], f[1], f[2], first, e));
    }
}

}  // namespace kelvin
