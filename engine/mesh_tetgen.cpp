// TetGen .node/.ele reader, and read_mesh's dispatch on the file extension.
#include <cctype>
#include <filesystem>
#include <vector>

#include "engine/mesh.hpp"
#include "engine/mesh_text_reader.hpp"

namespace kelvin {

Mesh read_tetgen(const std::string& path) {
  const std::filesystem::path p(path);
  const std::string stem = (p.parent_path() / p.stem()).string();
  const std::string node_path = stem + ".node", ele_path = stem + ".ele";
  Mesh m;
  m.source = ele_path;

  MeshTextReader nr(node_path);
  const auto nh =
      nr.numbers<long>(nr.require_line("the .node header", true), 4, "the .node header");
  if (nh[1] != 3) nr.fail("only 3-D .node files are supported");
  if (nh[2] < 0 || nh[3] < 0) nr.fail("negative attribute or boundary-marker count");
  const long nn = nh[0];
  if (nn <= 0) nr.fail("no nodes");
  // Counts are not trusted for allocation: a wrong one runs into the end of the file.
  std::vector<Eigen::Vector3d> pos;
  long first = -1;
  for (long k = 0; k < nn; ++k) {
    const auto v =
        nr.numbers<double>(nr.require_line("a node", true), 4, "a node (id x y z)", true);
    const long id = nr.integer(v[0], "node id");
    if (k == 0) {
      first = id;
      if (first != 0 && first != 1) nr.fail("node numbering must start at 0 or 1");
    }
    if (id != first + k)
      nr.fail(fmt::format("node {} out of sequence (expected {})", id, first + k));
    if (!Eigen::Vector3d(v[1], v[2], v[3]).allFinite())
      nr.fail("node coordinate is not a finite number");
    pos.emplace_back(v[1], v[2], v[3]);
  }
  m.nodes.resize(3, nn);
  for (long k = 0; k < nn; ++k) m.nodes.col(k) = pos[k];

  MeshTextReader er(ele_path);
  const auto eh = er.numbers<long>(er.require_line("the .ele header", true), 3, "the .ele header");
  if (eh[1] != 4) er.fail("only 4-node tetrahedra are supported (second header value must be 4)");
  const long ne = eh[0];
  if (ne <= 0) er.fail("no tetrahedra");
  if (eh[2] < 0 || eh[2] > 100) er.fail("the number of attributes must be between 0 and 100");
  std::vector<Eigen::Vector4i> tets;
  for (long e = 0; e < ne; ++e) {
    const auto v = er.numbers<long>(er.require_line("a tetrahedron", true), 5 + eh[2],
                                    "a tetrahedron (id, 4 nodes, attributes)");
    Eigen::Vector4i t;
    for (int k = 0; k < 4; ++k) {
      const long node = v[1 + k] - first;
      if (node < 0 || node >= nn)
        er.fail(fmt::format("tetrahedron {} refers to node {}, but {} defines nodes {}..{}", v[0],
                            v[1 + k], node_path, first, first + nn - 1));
      t[k] = static_cast<int>(node);
    }
    tets.push_back(t);
    m.region.push_back(eh[2] > 0 ? static_cast<int>(v[5]) : 0);
  }
  m.tets.resize(4, ne);
  for (long e = 0; e < ne; ++e) m.tets.col(e) = tets[e];
  return m;
}

Mesh read_mesh(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  Mesh mesh;
  if (ext == ".msh")
    mesh = read_gmsh(path);
  else if (ext == ".node" || ext == ".ele")
    mesh = read_tetgen(path);
  else
    throw Error(path + ": unknown mesh format '" + ext +
                "' (kelvin reads Gmsh .msh 2.2/4.1 and TetGen .node/.ele)");
  orient_tetrahedra(mesh);
  return mesh;
}

}  // namespace kelvin
