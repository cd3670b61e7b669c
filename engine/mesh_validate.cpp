#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <vector>

#include "base/error.hpp"
#include "engine/mesh.hpp"

namespace kelvin {

double tet_volume(const Mesh& m, int e) {
  const Eigen::Vector3d a = m.nodes.col(m.tets(0, e));
  return (m.nodes.col(m.tets(1, e)) - a)
             .cross(m.nodes.col(m.tets(2, e)) - a)
             .dot(m.nodes.col(m.tets(3, e)) - a) /
         6.0;
}

namespace {
/// Volumes at or below this share of the mean magnitude count as degenerate.
constexpr double kDegenerateVolume = 1e-12;

double mean_volume(const Mesh& m) {
  double mean = 0;
  for (int e = 0; e < m.num_tets(); ++e) mean += std::abs(tet_volume(m, e));
  return m.num_tets() ? mean / m.num_tets() : 0.0;
}
}  // namespace

void orient_tetrahedra(Mesh& m) {
  const int nn = m.num_nodes();
  for (int e = 0; e < m.num_tets(); ++e)
    for (int k = 0; k < 4; ++k)
      if (m.tets(k, e) < 0 || m.tets(k, e) >= nn) return;  // validate_mesh names it
  const double mean = mean_volume(m);
  for (int e = 0; e < m.num_tets(); ++e)
    if (tet_volume(m, e) < -kDegenerateVolume * mean) {
      std::swap(m.tets(2, e), m.tets(3, e));
      ++m.reordered;
    }
}

void validate_mesh(const Mesh& m) {
  const int nn = m.num_nodes(), ne = m.num_tets();
  // Both numberings, because users count from 1 and meshing tools often from 0.
  auto where = [&](int e) {
    return fmt::format("{}: tetrahedron {} (0-based index {}, 0-based nodes {} {} {} {})", m.source,
                       e + 1, e, m.tets(0, e), m.tets(1, e), m.tets(2, e), m.tets(3, e));
  };
  if (ne == 0) throw Error(m.source + ": the mesh has no tetrahedron");
  if (!m.region.empty() && static_cast<int>(m.region.size()) != ne)
    throw Error(m.source + ": region labels do not match the number of tetrahedra");
  for (int a = 0; a < nn; ++a)
    if (!m.nodes.col(a).allFinite())
      throw Error(
          fmt::format("{}: node {} (0-based index {}) has a non-finite coordinate (NaN or inf)",
                      m.source, a + 1, a));
  for (int e = 0; e < ne; ++e)
    for (int k = 0; k < 4; ++k)
      if (m.tets(k, e) < 0 || m.tets(k, e) >= nn)
        throw Error(fmt::format("{} refers to node {}, but the mesh has {} nodes", where(e),
                                m.tets(k, e), nn));
  const double mean = mean_volume(m);
  for (int e = 0; e < ne; ++e) {
    const double v = tet_volume(m, e);
    if (v < 0 && std::abs(v) > kDegenerateVolume * mean)
      throw Error(
          fmt::format("{} is inverted (negative volume {:.4g} m³): its nodes must be "
                      "ordered with positive orientation",
                      where(e), v));
    if (std::abs(v) <= kDegenerateVolume * mean)
      throw Error(
          fmt::format("{} is degenerate (volume {:.4g} m³, below 1e-12 of the mean {:.4g} m³)",
                      where(e), v, mean));
  }
  std::vector<char> used(nn, 0);
  for (int e = 0; e < ne; ++e)
    for (int k = 0; k < 4; ++k) used[m.tets(k, e)] = 1;
  for (int a = 0; a < nn; ++a)
    if (!used[a])
      throw Error(
          fmt::format("{}: node {} (0-based index {}) at ({:.6g}, {:.6g}, {:.6g}) is not "
                      "referenced by any tetrahedron",
                      m.source, a + 1, a, m.nodes(0, a), m.nodes(1, a), m.nodes(2, a)));
  // A triangle shared by three or more tets means overlapping or non-manifold input.
  std::map<std::array<int, 3>, std::vector<int>> faces;  // sorted face nodes → tets
  for (int e = 0; e < ne; ++e)
    for (int skip = 0; skip < 4; ++skip) {
      std::array<int, 3> f;
      for (int k = 0, j = 0; k < 4; ++k)
        if (k != skip) f[j++] = m.tets(k, e);
      std::sort(f.begin(), f.end());
      auto& tets = faces[f];
      tets.push_back(e);
      if (tets.size() > 2)
        throw Error(fmt::format(
            "{}: the face with 0-based nodes ({} {} {}) is shared by three tetrahedra, 0-based "
            "indices {}, {} and {} (1-based {}, {}, {}): the mesh is not manifold",
            m.source, f[0], f[1], f[2], tets[0], tets[1], tets[2], tets[0] + 1, tets[1] + 1,
            tets[2] + 1));
    }
}

}  // namespace kelvin
