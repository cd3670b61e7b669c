#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "base/error.hpp"
#include "engine/mesh.hpp"

namespace kelvin {
namespace {

/// Makes every tet positively oriented (swapping two nodes flips the sign).
void orient_positive(Mesh& m) {
  for (int e = 0; e < m.num_tets(); ++e)
    if (tet_volume(m, e) < 0) std::swap(m.tets(2, e), m.tets(3, e));
}

// A double: a hostile size overflows an int, never a comparison with a limit.
double cells_along_d(double extent, double h) {
  return std::max(1.0, std::round(extent / h));
}

/// For sizes the tet-count checks have bounded.
int cells_along(double extent, double h) {
  return static_cast<int>(cells_along_d(extent, h));
}

void check_size(double h, const char* what) {
  if (!(h > 0) || !std::isfinite(h))
    throw Error(fmt::format("{}: element size must be positive", what));
}

}  // namespace

double box_tet_count(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double h) {
  double cells = 1;
  for (int i = 0; i < 3; ++i) cells *= cells_along_d(hi[i] - lo[i], h);
  return 6 * cells;
}

// A disk of nr rings holds 6 nr² triangles; each prism layer cuts them into 3 tetrahedra.
double cylinder_tet_count(double radius, double length, double h) {
  const double nr = std::max(2.0, cells_along_d(radius, h));
  return 18 * nr * nr * cells_along_d(length, h);
}

Mesh generate_box(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double h) {
  check_size(h, "box");
  if (!((hi - lo).array() > 0).all()) throw Error("box: every side must have positive length");
  if (box_tet_count(lo, hi, h) > 1.2e8)
    throw Error("box: element size too small (more than 1.2e8 tetrahedra)");
  Eigen::Array3i n;
  for (int i = 0; i < 3; ++i) n[i] = cells_along(hi[i] - lo[i], h);
  const long total_cells = static_cast<long>(n[0]) * n[1] * n[2];
  Mesh m;
  m.source = fmt::format("generated box [{}, {}, {}]–[{}, {}, {}] h={}", lo[0], lo[1], lo[2], hi[0],
                         hi[1], hi[2], h);
  auto node = [&](int i, int j, int k) { return i + (n[0] + 1) * (j + (n[1] + 1) * k); };
  m.nodes.resize(3, (n[0] + 1) * (n[1] + 1) * (n[2] + 1));
  for (int k = 0; k <= n[2]; ++k)
    for (int j = 0; j <= n[1]; ++j)
      for (int i = 0; i <= n[0]; ++i)
        m.nodes.col(node(i, j, k)) =
            lo + ((hi - lo).array() * Eigen::Array3d(i, j, k) / n.cast<double>()).matrix();
  // Kuhn split (the six monotone paths across a cell's main diagonal), mirrored in
  // every direction from cell to cell: neighbours are reflections of each other
  // through their shared face, so the face diagonals agree (conforming), and the
  // mesh keeps the box's reflection symmetries. A single unmirrored diagonal
  // direction makes the discrete bar anisotropic: its two bending modes of a
  // square section split by 20% on 2 cells across.
  static const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  m.tets.resize(4, 6 * total_cells);
  int e = 0;
  for (int k = 0; k < n[2]; ++k)
    for (int j = 0; j < n[1]; ++j)
      for (int i = 0; i < n[0]; ++i)
        for (const auto& p : perms) {
          const Eigen::Array3i mirror(i & 1, j & 1, k & 1);
          Eigen::Array3i c = Eigen::Array3i(i, j, k) + mirror;  // start corner
          m.tets(0, e) = node(c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            c[p[s]] += mirror[p[s]] ? -1 : 1;
            m.tets(s + 1, e) = node(c[0], c[1], c[2]);
          }
          ++e;
        }
  m.region.assign(m.num_tets(), 0);
  orient_positive(m);
  return m;
}

Mesh generate_cylinder(double radius, double length, double h, int axis) {
  check_size(h, "cylinder");
  if (!(radius > 0) || !(length > 0)) throw Error("cylinder: radius and length must be positive");
  if (axis < 0 || axis > 2) throw Error("cylinder: axis must be 0, 1 or 2");
  // Disk: concentric rings k = 1..nr of 6k nodes around a centre node, stitched
  // ring to ring by angle (near-equilateral triangles); then prisms over nz layers.
  // At least two rings: a single hexagon loses 17% of the disk area.
  if (cylinder_tet_count(radius, length, h) > 3e8)
    throw Error("cylinder: element size too small (more than 3e8 tetrahedra)");
  const int nr = std::max(2, cells_along(radius, h)), nz = cells_along(length, h);
  std::vector<Eigen::Vector2d> disk{{0, 0}};
  std::vector<int> ring_start{0, 1};
  for (int k = 1; k <= nr; ++k) {
    for (int i = 0; i < 6 * k; ++i) {
      const double a = 2 * M_PI * i / (6 * k);
      disk.emplace_back(radius * k / nr * std::cos(a), radius * k / nr * std::sin(a));
    }
    ring_start.push_back(static_cast<int>(disk.size()));
  }
  std::vector<Eigen::Vector3i> tris;
  for (int k = 0; k < nr; ++k) {
    const int a0 = ring_start[k], na = ring_start[k + 1] - a0;
    const int b0 = ring_start[k + 1], nb = ring_start[k + 2] - b0;
    int i = 0, j = 0;
    // Advance along whichever ring's next node comes first in angle.
    while (i < (k == 0 ? 0 : na) || j < nb) {
      const double next_a = k == 0 || i >= na ? 1e9 : double(i + 1) / na;
      const double next_b = j >= nb ? 1e9 : double(j + 1) / nb;
      if (next_b <= next_a) {
        tris.emplace_back(a0 + (k == 0 ? 0 : i % na), b0 + j % nb, b0 + (j + 1) % nb);
        ++j;
      } else {
        tris.emplace_back(a0 + i % na, b0 + j % nb, a0 + (i + 1) % na);
        ++i;
      }
    }
  }
  const int nd = static_cast<int>(disk.size());
  Mesh m;
  m.source = fmt::format("generated cylinder r={} L={} h={}", radius, length, h);
  m.nodes.resize(3, nd * (nz + 1));
  for (int l = 0; l <= nz; ++l)
    for (int d = 0; d < nd; ++d) {
      const Eigen::Vector3d p(disk[d].x(), disk[d].y(), length * l / nz);
      // Cyclic permutation keeps the orientation: the cylinder axis becomes `axis`.
      m.nodes.col(l * nd + d) = axis == 2   ? p
                                : axis == 0 ? Eigen::Vector3d(p.z(), p.x(), p.y())
                                            : Eigen::Vector3d(p.y(), p.z(), p.x());
    }
  // Prism (v0 < v1 < v2 below, primes above) → 3 tets whose quad-face diagonals all
  // start at the face's lowest-numbered node, so neighbouring prisms agree.
  m.tets.resize(4, 3 * static_cast<long>(tris.size()) * nz);
  int e = 0;
  for (int l = 0; l < nz; ++l)
    for (Eigen::Vector3i t : tris) {
      std::sort(t.data(), t.data() + 3);
      const int v0 = l * nd + t[0], v1 = l * nd + t[1], v2 = l * nd + t[2];
      const int w0 = v0 + nd, w1 = v1 + nd, w2 = v2 + nd;
      m.tets.col(e++) << v0, v1, v2, w2;
      m.tets.col(e++) << v0, v1, w1, w2;
      m.tets.col(e++) << v0, w0, w1, w2;
    }
  m.region.assign(m.num_tets(), 0);
  orient_positive(m);
  return m;
}

}  // namespace kelvin
