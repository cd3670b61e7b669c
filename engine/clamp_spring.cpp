#include "engine/clamp_spring.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <map>

namespace kelvin {

std::vector<ClampFace> clamp_faces(const Mesh& mesh, const std::vector<int>& nodes, int clamp) {
  std::vector<char> held(mesh.num_nodes(), 0);
  for (int a : nodes) held[a] = 1;
  // A face bounds the body when one tetrahedron has it; count the held ones.
  static constexpr int kFace[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  std::map<std::array<int, 3>, std::pair<int, ClampFace>> seen;
  for (int e = 0; e < mesh.num_tets(); ++e)
    for (const auto& f : kFace) {
      ClampFace face;
      face.clamp = clamp;
      face.element = e;
      bool all = true;
      for (int k = 0; k < 3; ++k) {
        face.local[k] = f[k];
        face.nodes[k] = mesh.tets(f[k], e);
        all &= held[face.nodes[k]] != 0;
      }
      if (!all) continue;
      std::array<int, 3> key = face.nodes;
      std::sort(key.begin(), key.end());
      auto [it, fresh] = seen.try_emplace(key, 0, face);
      ++it->second.first;
    }
  std::vector<ClampFace> out;
  for (auto& [key, entry] : seen) {
    if (entry.first != 1) continue;
    ClampFace& f = entry.second;
    const Eigen::Vector3d a = mesh.nodes.col(f.nodes[0]), b = mesh.nodes.col(f.nodes[1]),
                          c = mesh.nodes.col(f.nodes[2]);
    f.area = 0.5 * (b - a).cross(c - a).norm();
    out.push_back(f);
  }
  // In element order, so that sums over faces do not depend on the map's key order.
  std::stable_sort(out.begin(), out.end(),
                   [](const ClampFace& x, const ClampFace& y) { return x.element < y.element; });
  return out;
}

}  // namespace kelvin
