// Gmsh ASCII .msh reader, formats 2.2 and 4.1. Only 4-node tetrahedra (type 4)
// are kept; nodes no tetrahedron uses (geometry points, surface-only nodes) are
// dropped and the rest renumbered compactly.
#include <array>
#include <cmath>
#include <map>
#include <unordered_map>

#include "engine/mesh.hpp"
#include "engine/mesh_text_reader.hpp"

namespace kelvin {
namespace {

struct RawMesh {
  std::unordered_map<long, Eigen::Vector3d> nodes;  // gmsh tag → position
  std::vector<std::array<long, 4>> tets;
  std::vector<int> region;
  std::vector<int> line;  // where each tet was read, for "refers to a missing node" errors
};

/// A count from a header: negative counts are malformed; huge ones simply run
/// into the end of the file, so nothing is preallocated from them.
long count(MeshTextReader& r, long n, const char* what) {
  if (n < 0) r.fail(fmt::format("negative {} ({})", what, n));
  return n;
}

Eigen::Vector3d point(MeshTextReader& r, double x, double y, double z) {
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z))
    r.fail("node coordinate is not a finite number");
  return {x, y, z};
}

void add_tet(MeshTextReader& r, RawMesh& m, std::array<long, 4> nodes, int region) {
  m.tets.push_back(nodes);
  m.region.push_back(region);
  m.line.push_back(r.line());
}

void skip_section(MeshTextReader& r, const std::string& name) {
  const std::string end = "$End" + name.substr(1);
  std::string s;
  while (r.next_line(s))
    if (s.rfind(end, 0) == 0) return;
  r.fail("section " + name + " is not closed by " + end);
}

void read_v2(MeshTextReader& r, RawMesh& m) {
  std::string s;
  while (r.next_line(s)) {
    if (s == "$Nodes") {
      const long n =
          count(r, r.numbers<long>(r.require_line("the node count"), 1, "the node count")[0],
                "node count");
      for (long k = 0; k < n; ++k) {
        const auto v = r.numbers<double>(r.require_line("a node"), 4, "a node (tag x y z)");
        m.nodes[r.integer(v[0], "node tag")] = point(r, v[1], v[2], v[3]);
      }
      if (r.require_line("$EndNodes") != "$EndNodes") r.fail("expected $EndNodes");
    } else if (s == "$Elements") {
      const long n =
          count(r, r.numbers<long>(r.require_line("the element count"), 1, "the element count")[0],
                "element count");
      for (long k = 0; k < n; ++k) {
        const auto v = r.numbers<long>(r.require_line("an element"), 3, "an element", true);
        const long type = v[1], ntags = v[2];
        if (type != 4) continue;
        if (static_cast<long>(v.size()) != 3 + ntags + 4)
          r.fail("a tetrahedron needs tag count, tags and 4 node tags");
        add_tet(r, m, {v[3 + ntags], v[4 + ntags], v[5 + ntags], v[6 + ntags]},
                ntags > 0 ? static_cast<int>(v[3]) : 0);
      }
      if (r.require_line("$EndElements") != "$EndElements") r.fail("expected $EndElements");
    } else if (!s.empty() && s[0] == '$' && s.rfind("$End", 0) != 0) {
      skip_section(r, s);
    }
  }
}

void read_v41(MeshTextReader& r, RawMesh& m) {
  std::map<int, int> volume_group;  // volume entity tag → first physical tag
  std::string s;
  while (r.next_line(s)) {
    if (s == "$Entities") {
      const auto c = r.numbers<long>(r.require_line("entity counts"), 4, "entity counts");
      for (long k = 0; k < c[0]; ++k) r.require_line("a point entity");
      for (long k = 0; k < c[1] + c[2]; ++k) r.require_line("a curve or surface entity");
      for (long k = 0; k < c[3]; ++k) {
        const auto v =
            r.numbers<double>(r.require_line("a volume entity"), 8, "a volume entity", true);
        const long nphys = r.integer(v[7], "physical tag count");
        if (static_cast<long>(v.size()) < 8 + nphys)
          r.fail("volume entity lists fewer physical tags than announced");
        volume_group[static_cast<int>(r.integer(v[0], "entity tag"))] =
            nphys > 0 ? static_cast<int>(r.integer(v[8], "physical tag")) : 0;
      }
      if (r.require_line("$EndEntities") != "$EndEntities") r.fail("expected $EndEntities");
    } else if (s == "$Nodes") {
      const auto h = r.numbers<long>(r.require_line("the node header"), 4, "the node header");
      for (long b = 0; b < h[0]; ++b) {
        const auto bh =
            r.numbers<long>(r.require_line("a node block header"), 4, "a node block header");
        if (bh[2] != 0) r.fail("parametric nodes are not supported");
        const long n = count(r, bh[3], "number of nodes in the block");
        std::vector<long> tags;
        for (long k = 0; k < n; ++k)
          tags.push_back(r.numbers<long>(r.require_line("a node tag"), 1, "a node tag")[0]);
        for (long k = 0; k < n; ++k) {
          const auto v =
              r.numbers<double>(r.require_line("node coordinates"), 3, "node coordinates");
          m.nodes[tags[k]] = point(r, v[0], v[1], v[2]);
        }
      }
      if (r.require_line("$EndNodes") != "$EndNodes") r.fail("expected $EndNodes");
    } else if (s == "$Elements") {
      const auto h = r.numbers<long>(r.require_line("the element header"), 4, "the element header");
      for (long b = 0; b < h[0]; ++b) {
        const auto bh = r.numbers<long>(r.require_line("an element block header"), 4,
                                        "an element block header");
        const int dim = static_cast<int>(bh[0]), entity = static_cast<int>(bh[1]);
        const long type = bh[2], n = count(r, bh[3], "number of elements in the block");
        for (long k = 0; k < n; ++k) {
          const std::string line = r.require_line("an element");
          if (type != 4) continue;
          const auto v = r.numbers<long>(line, 5, "a tetrahedron (tag and 4 node tags)");
          const auto g = volume_group.find(entity);
          add_tet(r, m, {v[1], v[2], v[3], v[4]},
                  dim == 3 && g != volume_group.end() ? g->second : 0);
        }
      }
      if (r.require_line("$EndElements") != "$EndElements") r.fail("expected $EndElements");
    } else if (!s.empty() && s[0] == '$' && s.rfind("$End", 0) != 0) {
      skip_section(r, s);
    }
  }
}

}  // namespace

Mesh read_gmsh(const std::string& path) {
  MeshTextReader r(path);
  if (r.require_line("$MeshFormat") != "$MeshFormat")
    r.fail("not a Gmsh file: expected $MeshFormat");
  const std::string fmtline = r.require_line("the format line");
  std::istringstream ss(fmtline);
  std::string version;
  int file_type = -1, data_size = 0;
  if (!(ss >> version >> file_type >> data_size))
    r.fail("malformed format line, expected 'version file-type data-size'");
  if (file_type != 0)
    r.fail("binary .msh files are not supported: export as ASCII (Gmsh: -format msh41 -bin 0)");
  if (version != "2.2" && version != "4.1" && version != "2" && version != "4")
    r.fail("unsupported .msh version " + version + " (kelvin reads 2.2 and 4.1)");
  if (r.require_line("$EndMeshFormat") != "$EndMeshFormat") r.fail("expected $EndMeshFormat");
  RawMesh raw;
  if (version[0] == '2')
    read_v2(r, raw);
  else
    read_v41(r, raw);
  if (raw.tets.empty())
    throw Error(fmt::format("{}:{}: no tetrahedra (element type 4) in the file", path, r.line()));

  Mesh m;
  m.source = path;
  std::unordered_map<long, int> index;
  std::vector<Eigen::Vector3d> pos;
  m.tets.resize(4, raw.tets.size());
  for (size_t e = 0; e < raw.tets.size(); ++e)
    for (int k = 0; k < 4; ++k) {
      const long tag = raw.tets[e][k];
      auto it = index.find(tag);
      if (it == index.end()) {
        const auto node = raw.nodes.find(tag);
        if (node == raw.nodes.end())
          throw Error(
              fmt::format("{}:{}: tetrahedron refers to node {}, which $Nodes does not define",
                          path, raw.line[e], tag));
        it = index.emplace(tag, static_cast<int>(pos.size())).first;
        pos.push_back(node->second);
      }
      m.tets(k, e) = it->second;
    }
  m.nodes.resize(3, pos.size());
  for (size_t a = 0; a < pos.size(); ++a) m.nodes.col(a) = pos[a];
  m.region = raw.region;
  return m;
}

}  // namespace kelvin
