#include "engine/selection.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "base/error.hpp"

namespace kelvin {

std::vector<int> select_nodes(const Mesh& mesh, const NodeSelection& sel) {
  std::vector<int> out;
  const int nn = mesh.num_nodes();
  if (nn == 0 && sel.kind != NodeSelection::Kind::Ids) return out;
  switch (sel.kind) {
    case NodeSelection::Kind::Plane: {
      if (sel.axis < 0 || sel.axis > 2)
        throw Error(fmt::format("plane selection: axis {} is not 0 (x), 1 (y) or 2 (z)", sel.axis));
      double tol = sel.tolerance;
      if (tol < 0) {
        const Eigen::Vector3d span =
            mesh.nodes.rowwise().maxCoeff() - mesh.nodes.rowwise().minCoeff();
        tol = 1e-6 * span.norm();
      }
      for (int a = 0; a < nn; ++a)
        if (std::abs(mesh.nodes(sel.axis, a) - sel.at) <= tol) out.push_back(a);
      break;
    }
    case NodeSelection::Kind::Box:
      for (int a = 0; a < nn; ++a)
        if ((mesh.nodes.col(a).array() >= sel.lo.array()).all() &&
            (mesh.nodes.col(a).array() <= sel.hi.array()).all())
          out.push_back(a);
      break;
    case NodeSelection::Kind::Ids:
      for (int id : sel.ids) {
        if (id < 0 || id >= nn)
          throw Error(fmt::format("{}: node id {} is out of range (the mesh has nodes 0..{})",
                                  mesh.source, id, nn - 1));
        out.push_back(id);
      }
      std::sort(out.begin(), out.end());
      out.erase(std::unique(out.begin(), out.end()), out.end());
      break;
  }
  return out;
}

}  // namespace kelvin
