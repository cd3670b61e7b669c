#include "engine/selection.hpp"

#include <algorithm>
#include <cmath>

namespace kelvin {

std::vector<int> select_nodes(const Mesh& mesh, const NodeSelection& sel) {
  std::vector<int> out;
  const int nn = mesh.num_nodes();
  switch (sel.kind) {
    case NodeSelection::Kind::Plane: {
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
      for (int id : sel.ids)
        if (id >= 0 && id < nn) out.push_back(id);
      std::sort(out.begin(), out.end());
      out.erase(std::unique(out.begin(), out.end()), out.end());
      break;
  }
  return out;
}

}  // namespace kelvin
