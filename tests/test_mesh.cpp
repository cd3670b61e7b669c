// Mesh generators, readers, validation and node selections.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <sstream>
#include <string>

#include "base/error.hpp"
#include "engine/mesh.hpp"
#include "engine/mesh_refine.hpp"
#include "engine/selection.hpp"

using kelvin::Mesh;

namespace {

const std::string kMeshes = std::string(KELVIN_TEST_DATA) + "/meshes/";

double total_volume(const Mesh& m) {
  double v = 0;
  for (int e = 0; e < m.num_tets(); ++e) v += kelvin::tet_volume(m, e);
  return v;
}

double min_volume(const Mesh& m) {
  double v = INFINITY;
  for (int e = 0; e < m.num_tets(); ++e) v = std::min(v, kelvin::tet_volume(m, e));
  return v;
}

/// Message of the kelvin::Error thrown by f, or "" when nothing is thrown.
template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const kelvin::Error& e) {
    return e.what();
  }
  return "";
}

/// Unit cube as 6 Kuhn tets, the same mesh as the fixtures cube_v22/v41 and cube.node/ele.
Mesh unit_cube() {
  return kelvin::generate_box({0, 0, 0}, {1, 1, 1}, 1.0);
}

}  // namespace

TEST(GenerateBox, VolumeIsExactAndTetsArePositive) {
  const Mesh m = kelvin::generate_box({-0.1, 0, 0.2}, {0.2, 0.05, 0.6}, 0.05);
  EXPECT_EQ(m.num_nodes(), 7 * 2 * 9);  // 6 × 1 × 8 cells
  EXPECT_EQ(m.num_tets(), 6 * 6 * 1 * 8);
  EXPECT_NEAR(total_volume(m), 0.3 * 0.05 * 0.4, 1e-15);
  EXPECT_GT(min_volume(m), 0);
  EXPECT_EQ(m.region.size(), static_cast<size_t>(m.num_tets()));
  EXPECT_NO_THROW(kelvin::validate_mesh(m));  // conforming: no face shared by three tets
}

// Red refinement of a file's mesh (two regions, dolfin's node order reoriented):
// eight children per tetrahedron filling it exactly, one node per edge, conforming
// and positively oriented, the regions kept, the original nodes first and unmoved.
TEST(RefineMesh, SplitsEveryTetrahedronIntoEightConformingChildren) {
  Mesh m = kelvin::generate_box({0, 0, 0}, {0.03, 0.02, 0.05}, 0.01);
  for (int e = 0; e < m.num_tets(); ++e) m.region[e] = e % 2 ? 7 : 3;
  std::set<std::pair<int, int>> edges;
  for (int e = 0; e < m.num_tets(); ++e)
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) edges.insert(std::minmax(m.tets(a, e), m.tets(b, e)));
  const Mesh r = kelvin::refine_uniformly(m);
  EXPECT_EQ(r.num_tets(), 8 * m.num_tets());
  EXPECT_EQ(r.num_nodes(), m.num_nodes() + static_cast<int>(edges.size()));
  EXPECT_TRUE(r.nodes.leftCols(m.num_nodes()).isApprox(m.nodes, 0));
  EXPECT_NEAR(total_volume(r), total_volume(m), 1e-15);
  EXPECT_GT(min_volume(r), 0);
  EXPECT_NO_THROW(kelvin::validate_mesh(r));
  double largest_child = 0;
  for (int e = 0; e < m.num_tets(); ++e) {
    double children = 0;
    for (int k = 0; k < 8; ++k) {
      EXPECT_EQ(r.region[8 * e + k], m.region[e]);
      children += kelvin::tet_volume(r, 8 * e + k);
      largest_child =
          std::max(largest_child, kelvin::tet_volume(r, 8 * e + k) / kelvin::tet_volume(m, e));
    }
    EXPECT_NEAR(children, kelvin::tet_volume(m, e), 1e-12 * kelvin::tet_volume(m, e));
  }
  // Every child of a red refinement is an eighth of its parent, octahedron's too.
  EXPECT_NEAR(largest_child, 0.125, 1e-9);
  EXPECT_EQ(kelvin::refine_uniformly(m, 2).num_tets(), 64 * m.num_tets());
  EXPECT_EQ(kelvin::refine_uniformly(m, 0).num_tets(), m.num_tets());
}

TEST(GenerateBox, AtLeastOneCellPerDirection) {
  const Mesh m = kelvin::generate_box({0, 0, 0}, {1, 0.01, 1}, 0.5);
  EXPECT_EQ(m.num_tets(), 6 * 2 * 1 * 2);
  EXPECT_NEAR(total_volume(m), 0.01, 1e-15);
}

TEST(GenerateBox, RejectsBadInput) {
  EXPECT_THROW(kelvin::generate_box({0, 0, 0}, {1, 1, 1}, 0), kelvin::Error);
  EXPECT_THROW(kelvin::generate_box({0, 0, 0}, {1, -1, 1}, 0.1), kelvin::Error);
}

TEST(GenerateCylinder, VolumeConvergesToPiR2L) {
  const double r = 0.01, L = 0.2, exact = M_PI * r * r * L;
  double previous_error = 1;
  for (double h : {r / 2, r / 4, r / 8}) {
    const Mesh m = kelvin::generate_cylinder(r, L, h, 2);
    EXPECT_GT(min_volume(m), 0) << "h=" << h;
    EXPECT_NO_THROW(kelvin::validate_mesh(m));
    const double err = std::abs(total_volume(m) - exact) / exact;
    EXPECT_LT(err, previous_error) << "h=" << h;
    previous_error = err;
    if (h == r / 4) {
      EXPECT_LT(err, 0.02);
    }
  }
  EXPECT_LT(previous_error, 0.005);  // h = r/8
}

// The counts a scenario checks before generating are the generators' own.
TEST(GenerateMesh, TetCountsArePredictedExactly) {
  for (double h : {0.5, 0.3, 0.07}) {
    const Eigen::Vector3d lo(0, 0, 0), hi(1, 0.4, 2.2);
    EXPECT_EQ(kelvin::box_tet_count(lo, hi, h), kelvin::generate_box(lo, hi, h).num_tets());
    for (double r : {0.05, 0.31, 0.9})
      EXPECT_EQ(kelvin::cylinder_tet_count(r, 1.3, h),
                kelvin::generate_cylinder(r, 1.3, h, 2).num_tets())
          << "r=" << r << " h=" << h;
  }
  EXPECT_GT(kelvin::cylinder_tet_count(1, 1, 1e-300), 1e300);  // no overflow to a small count
}

TEST(GenerateCylinder, GeometryAlongEachAxis) {
  for (int axis = 0; axis < 3; ++axis) {
    const Mesh m = kelvin::generate_cylinder(0.01, 0.2, 0.004, axis);
    EXPECT_NEAR(m.nodes.row(axis).minCoeff(), 0, 1e-15);
    EXPECT_NEAR(m.nodes.row(axis).maxCoeff(), 0.2, 1e-15);
    for (int a = 0; a < m.num_nodes(); ++a) {
      Eigen::Vector3d radial = m.nodes.col(a);
      radial[axis] = 0;
      EXPECT_LE(radial.norm(), 0.01 * (1 + 1e-12));
    }
    EXPECT_GT(min_volume(m), 0);
    EXPECT_NE(m.source.find("cylinder"), std::string::npos);
  }
}

TEST(GenerateCylinder, ReasonableQuality) {
  // Volume against the cube of the longest edge: the regular tet scores 0.118, a
  // Kuhn tet of a cube 0.032, a sliver orders of magnitude less.
  const Mesh m = kelvin::generate_cylinder(0.01, 0.05, 0.0025);
  double worst = INFINITY;
  for (int e = 0; e < m.num_tets(); ++e) {
    double longest = 0;
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j)
        longest = std::max(longest, (m.nodes.col(m.tets(i, e)) - m.nodes.col(m.tets(j, e))).norm());
    worst = std::min(worst, kelvin::tet_volume(m, e) / std::pow(longest, 3));
  }
  EXPECT_GT(worst, 0.015);
}

TEST(ReadGmsh, Versions22And41GiveTheSameMesh) {
  const Mesh a = kelvin::read_mesh(kMeshes + "cube_v22.msh");
  const Mesh b = kelvin::read_mesh(kMeshes + "cube_v41.msh");
  const Mesh ref = unit_cube();
  for (const Mesh* m : {&a, &b}) {
    ASSERT_EQ(m->num_nodes(), 8);  // node 99 and the triangle-only use are dropped
    ASSERT_EQ(m->num_tets(), 6);
    EXPECT_EQ(m->region, (std::vector<int>{1, 1, 1, 2, 2, 2}));
    EXPECT_NEAR(total_volume(*m), 1.0, 1e-15);
    EXPECT_GT(min_volume(*m), 0);
    EXPECT_NO_THROW(kelvin::validate_mesh(*m));
    // Same tets as the generator once renumbered back through the positions.
    for (int e = 0; e < 6; ++e)
      for (int k = 0; k < 4; ++k)
        EXPECT_EQ(m->nodes.col(m->tets(k, e)), ref.nodes.col(ref.tets(k, e)));
  }
  EXPECT_EQ(a.nodes, b.nodes);
  EXPECT_EQ(a.tets, b.tets);
  EXPECT_EQ(a.source, kMeshes + "cube_v22.msh");
}

TEST(ReadTetgen, EitherFileGivesTheMeshWithRegions) {
  const Mesh ref = kelvin::read_mesh(kMeshes + "cube_v22.msh");
  for (const char* name : {"cube.node", "cube.ele"}) {
    const Mesh m = kelvin::read_mesh(kMeshes + name);
    ASSERT_EQ(m.num_nodes(), 8);
    ASSERT_EQ(m.num_tets(), 6);
    EXPECT_EQ(m.region, (std::vector<int>{1, 1, 1, 2, 2, 2}));
    EXPECT_NEAR(total_volume(m), 1.0, 1e-15);
    for (int e = 0; e < 6; ++e)
      for (int k = 0; k < 4; ++k)
        EXPECT_EQ(m.nodes.col(m.tets(k, e)), ref.nodes.col(ref.tets(k, e)));
  }
}

struct MalformedCase {
  const char* file;
  const char* location;  // "file:line"
  const char* words;     // part of the explanation
};

class MalformedMesh : public testing::TestWithParam<MalformedCase> {};

TEST_P(MalformedMesh, ErrorNamesFileAndLine) {
  const MalformedCase& c = GetParam();
  const std::string msg = error_of([&] { kelvin::read_mesh(kMeshes + c.file); });
  EXPECT_NE(msg.find(kMeshes + c.location + ":"), std::string::npos) << msg;
  EXPECT_NE(msg.find(c.words), std::string::npos) << msg;
}

INSTANTIATE_TEST_SUITE_P(
    Files, MalformedMesh,
    testing::Values(MalformedCase{"bad_truncated_nodes.msh", "bad_truncated_nodes.msh:14",
                                  "unexpected end of file"},
                    MalformedCase{"bad_missing_node.msh", "bad_missing_node.msh:24", "node 80"},
                    MalformedCase{"bad_binary.msh", "bad_binary.msh:2", "ASCII"},
                    MalformedCase{"bad_number.msh", "bad_number.msh:33", "'0x' is not a number"},
                    MalformedCase{"bad.ele", "bad.ele:5", "node 9"},
                    // Found by scripts/fuzz.sh: a count or a tag beyond the integer
                    // range had been cast to an integer (undefined behaviour).
                    MalformedCase{"fuzz_count_2e48.node", "fuzz_count_2e48.node:2",
                                  "is not an integer"},
                    MalformedCase{"fuzz_node_tag_1e25.msh", "fuzz_node_tag_1e25.msh",
                                  "node tag 1e+25 is not an integer"},
                    MalformedCase{"fuzz_entity_tag_3e107.msh", "fuzz_entity_tag_3e107.msh",
                                  "is not an integer"},
                    MalformedCase{"fuzz_node_id_9e28.node", "fuzz_node_id_9e28.node", "node id"}));

// Every prefix of a valid file, and random byte corruptions of it, must end in a
// kelvin::Error or a mesh, never a crash, a hang or another exception type.
TEST(ReadGmsh, TruncatedOrCorruptedFilesOnlyEverThrowKelvinError) {
  const auto dir = std::filesystem::temp_directory_path() / "kelvin_test_mesh_fuzz";
  std::filesystem::create_directories(dir);
  std::mt19937 rng(7);
  for (const char* name : {"cube_v22.msh", "cube_v41.msh"}) {
    std::ifstream in(kMeshes + name, std::ios::binary);
    std::stringstream buf;
    buf << in.rdbuf();
    const std::string text = buf.str();
    const std::string path = (dir / name).string();
    auto attempt = [&](const std::string& content) {
      std::ofstream(path, std::ios::binary) << content;
      try {
        kelvin::read_mesh(path);
      } catch (const kelvin::Error& e) {
        EXPECT_EQ(std::string(e.what()).rfind(path, 0), 0u) << e.what();
      }
    };
    for (size_t n = 0; n < text.size(); n += 3) attempt(text.substr(0, n));
    for (int k = 0; k < 300; ++k) {
      std::string t = text;
      t[rng() % t.size()] = static_cast<char>(rng() % 256);
      attempt(t);
    }
  }
  std::filesystem::remove_all(dir);
}

TEST(ReadMesh, UnknownExtensionAndMissingFile) {
  std::string msg = error_of([] { kelvin::read_mesh("foo.stl"); });
  EXPECT_NE(msg.find("foo.stl"), std::string::npos) << msg;
  EXPECT_NE(msg.find(".msh"), std::string::npos) << msg;
  EXPECT_NE(msg.find(".node"), std::string::npos) << msg;
  msg = error_of([] { kelvin::read_mesh(kMeshes + "does_not_exist.msh"); });
  EXPECT_NE(msg.find("does_not_exist.msh"), std::string::npos) << msg;
}

// dolfin (and other tools) list some tetrahedra in negative orientation; the reader
// reorders their nodes and counts them, and the mesh is then the same solid.
TEST(ReadGmsh, NegativelyOrderedTetrahedraAreReorderedAndCounted) {
  const Mesh ref = kelvin::read_mesh(kMeshes + "cube_v22.msh");
  const Mesh m = kelvin::read_mesh(kMeshes + "cube_dolfin_v22.msh");
  EXPECT_EQ(ref.reordered, 0);
  EXPECT_EQ(m.reordered, 3);  // elements 4, 6 and 8 of the file have two nodes swapped
  ASSERT_EQ(m.num_tets(), ref.num_tets());
  EXPECT_GT(min_volume(m), 0);
  EXPECT_NEAR(total_volume(m), 1.0, 1e-14);
  for (int e = 0; e < m.num_tets(); ++e)
    EXPECT_NEAR(kelvin::tet_volume(m, e), kelvin::tet_volume(ref, e), 1e-15) << e;
  EXPECT_EQ(m.region, ref.region);
  EXPECT_NO_THROW(kelvin::validate_mesh(m));
}

TEST(ValidateMesh, InvertedTetIsNamed) {
  Mesh m = unit_cube();
  m.source = "cube";
  std::swap(m.tets(0, 4), m.tets(1, 4));
  const std::string msg = error_of([&] { kelvin::validate_mesh(m); });
  EXPECT_NE(msg.find("tetrahedron 5 (0-based index 4"), std::string::npos) << msg;
  EXPECT_NE(msg.find("inverted (negative volume -0.1667"), std::string::npos) << msg;
}

TEST(ValidateMesh, DegenerateTetIsNamed) {
  Mesh m = unit_cube();
  // A seventh, flat tet: its fourth node sits on the edge between two of the others.
  m.nodes.conservativeResize(3, 9);
  m.nodes.col(8) = 0.5 * (m.nodes.col(m.tets(1, 2)) + m.nodes.col(m.tets(2, 2)));
  m.tets.conservativeResize(4, 7);
  m.tets.col(6) << m.tets(0, 2), m.tets(1, 2), m.tets(2, 2), 8;
  m.region.push_back(0);
  const std::string msg = error_of([&] { kelvin::validate_mesh(m); });
  EXPECT_NE(msg.find("tetrahedron 7 (0-based index 6"), std::string::npos) << msg;
  EXPECT_NE(msg.find("degenerate"), std::string::npos) << msg;
}

TEST(ValidateMesh, UnreferencedNodeIsNamed) {
  Mesh m = unit_cube();
  m.nodes.conservativeResize(3, 9);
  m.nodes.col(8) << 3, 3, 3;
  const std::string msg = error_of([&] { kelvin::validate_mesh(m); });
  EXPECT_NE(msg.find("0-based index 8"), std::string::npos) << msg;
  EXPECT_NE(msg.find("not referenced"), std::string::npos) << msg;
}

TEST(ValidateMesh, NonManifoldFaceIsNamed) {
  // Two tets on either side of face (0 1 2) are fine; a third one on it is not.
  Mesh m;
  m.source = "fan";
  m.nodes.resize(3, 6);
  m.nodes << 0, 1, 0, 0.2, 0.3, 0.1,  //
      0, 0, 1, 0.2, 0.3, 0.5,         //
      0, 0, 0, 1, -1, 2;
  m.tets.resize(4, 3);
  m.tets.col(0) << 0, 1, 2, 3;
  m.tets.col(1) << 0, 2, 1, 4;
  m.tets.col(2) << 0, 1, 2, 5;
  m.region.assign(3, 0);
  ASSERT_GT(kelvin::tet_volume(m, 0), 0);
  ASSERT_GT(kelvin::tet_volume(m, 1), 0);
  ASSERT_GT(kelvin::tet_volume(m, 2), 0);
  const std::string msg = error_of([&] { kelvin::validate_mesh(m); });
  EXPECT_NE(msg.find("(0 1 2)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("0, 1 and 2"), std::string::npos) << msg;
  EXPECT_NE(msg.find("not manifold"), std::string::npos) << msg;
}

TEST(ValidateMesh, EmptyNaNAndOutOfRange) {
  Mesh empty;
  empty.source = "empty";
  EXPECT_NE(error_of([&] { kelvin::validate_mesh(empty); }).find("no tetrahedron"),
            std::string::npos);
  Mesh m = unit_cube();
  m.nodes(1, 3) = NAN;
  EXPECT_NE(error_of([&] { kelvin::validate_mesh(m); }).find("0-based index 3"), std::string::npos);
  m = unit_cube();
  m.tets(2, 1) = 8;
  const std::string msg = error_of([&] { kelvin::validate_mesh(m); });
  EXPECT_NE(msg.find("tetrahedron 2 (0-based index 1"), std::string::npos) << msg;
  EXPECT_NE(msg.find("node 8"), std::string::npos) << msg;
}

TEST(SelectNodes, PlaneBoxAndIds) {
  const Mesh m = kelvin::generate_box({0, 0, 0}, {0.1, 0.1, 0.2}, 0.05);  // 3 × 3 × 5 nodes
  kelvin::NodeSelection top;
  top.axis = 2;
  top.at = 0.2;
  const auto t = kelvin::select_nodes(m, top);
  ASSERT_EQ(t.size(), 9u);
  for (int a : t) EXPECT_NEAR(m.nodes(2, a), 0.2, 1e-15);
  EXPECT_TRUE(std::is_sorted(t.begin(), t.end()));

  top.at = 0.2 + 1e-3;  // off the nodes: empty without throwing, or found with a tolerance
  EXPECT_TRUE(kelvin::select_nodes(m, top).empty());
  top.tolerance = 2e-3;
  EXPECT_EQ(kelvin::select_nodes(m, top), t);

  kelvin::NodeSelection box;
  box.kind = kelvin::NodeSelection::Kind::Box;
  box.lo = {-1, -1, -1};
  box.hi = {0.06, 1, 0.01};  // x ∈ {0, 0.05}, z = 0
  EXPECT_EQ(kelvin::select_nodes(m, box).size(), 2u * 3u);

  kelvin::NodeSelection ids;
  ids.kind = kelvin::NodeSelection::Kind::Ids;
  ids.ids = {7, 3, 7, 0};
  EXPECT_EQ(kelvin::select_nodes(m, ids), (std::vector<int>{0, 3, 7}));
  ids.ids = {45};
  EXPECT_THROW(kelvin::select_nodes(m, ids), kelvin::Error);
}
