#include "engine/mesh_refine.hpp"

#include <fmt/format.h>

#include <array>
#include <cstdint>
#include <unordered_map>
#include <utility>

namespace kelvin {
namespace {

Mesh refine_once(const Mesh& m) {
  Mesh out;
  out.source = m.source;
  out.reordered = m.reordered;
  const int nn = m.num_nodes(), ne = m.num_tets();
  std::unordered_map<std::uint64_t, int> midpoint;
  std::vector<Eigen::Vector3d> added;
  const auto mid = [&](int a, int b) {
    if (a > b) std::swap(a, b);
    const std::uint64_t key = (std::uint64_t(a) << 32) | std::uint64_t(b);
    const auto [it, inserted] = midpoint.emplace(key, nn + static_cast<int>(added.size()));
    if (inserted) added.push_back(0.5 * (m.nodes.col(a) + m.nodes.col(b)));
    return it->second;
  };
  std::vector<std::array<int, 4>> tets;
  tets.reserve(8 * static_cast<std::size_t>(ne));
  out.region.reserve(8 * static_cast<std::size_t>(ne));
  for (int e = 0; e < ne; ++e) {
    const int v0 = m.tets(0, e), v1 = m.tets(1, e), v2 = m.tets(2, e), v3 = m.tets(3, e);
    const int a = mid(v0, v1), b = mid(v0, v2), c = mid(v0, v3), d = mid(v1, v2), f = mid(v1, v3),
              g = mid(v2, v3);
    std::array<std::array<int, 4>, 8> kids = {
        {{v0, a, b, c}, {a, v1, d, f}, {b, d, v2, g}, {c, f, g, v3}}};
    // The octahedron a b c d f g: its three diagonals a–g, b–f, c–d; the shortest one
    // keeps the children's shapes from degrading over levels.
    const auto len = [&](int p, int q) {
      const auto P = [&](int i) -> Eigen::Vector3d {
        return i < nn ? Eigen::Vector3d(m.nodes.col(i)) : added[i - nn];
      };
      return (P(p) - P(q)).squaredNorm();
    };
    const double ag = len(a, g), bf = len(b, f), cd = len(c, d);
    if (ag <= bf && ag <= cd)
      kids[4] = {a, g, b, c}, kids[5] = {a, g, c, f}, kids[6] = {a, g, f, d},
      kids[7] = {a, g, d, b};
    else if (bf <= cd)
      kids[4] = {b, f, a, c}, kids[5] = {b, f, c, g}, kids[6] = {b, f, g, d},
      kids[7] = {b, f, d, a};
    else
      kids[4] = {c, d, a, b}, kids[5] = {c, d, b, g}, kids[6] = {c, d, g, f},
      kids[7] = {c, d, f, a};
    for (const auto& k : kids) {
      tets.push_back(k);
      out.region.push_back(m.region.empty() ? 0 : m.region[e]);
    }
  }
  out.nodes.resize(3, nn + static_cast<long>(added.size()));
  out.nodes.leftCols(nn) = m.nodes;
  for (std::size_t i = 0; i < added.size(); ++i)
    out.nodes.col(nn + static_cast<long>(i)) = added[i];
  out.tets.resize(4, static_cast<long>(tets.size()));
  for (std::size_t e = 0; e < tets.size(); ++e) {
    for (int k = 0; k < 4; ++k) out.tets(k, static_cast<long>(e)) = tets[e][k];
    if (tet_volume(out, static_cast<int>(e)) < 0)
      std::swap(out.tets(2, static_cast<long>(e)), out.tets(3, static_cast<long>(e)));
  }
  return out;
}

}  // namespace

Mesh refine_uniformly(const Mesh& mesh, int levels) {
  Mesh out = mesh;
  for (int l = 0; l < levels; ++l) out = refine_once(out);
  if (levels > 0) out.source = fmt::format("{} (refined {}×)", mesh.source, levels);
  out.refined = mesh.refined + levels;
  return out;
}

}  // namespace kelvin
