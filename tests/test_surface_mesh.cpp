// A closed STL surface becomes a volume mesh kelvin reads, as the README says:
// Gmsh (installed by scripts/install-deps.sh) on yaml/examples/silicone-beam/beam.geo.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "engine/mesh.hpp"
#include "tests/test_support.hpp"

namespace kelvin {

TEST(SurfaceMesh, TheBeamsStlBecomesATetrahedralMeshOfItsVolume) {
  const auto dir = test::scratch("surface-mesh");
  const std::string geo = std::string(KELVIN_SOURCE_DIR) + "/yaml/examples/silicone-beam/beam.geo";
  const std::string msh = (dir / "beam.msh").string();
  const int status = std::system(
      ("gmsh -3 " + geo + " -o " + msh + " > " + (dir / "gmsh.log").string() + " 2>&1").c_str());
  ASSERT_EQ(status, 0) << "gmsh failed (scripts/install-deps.sh installs it): "
                       << test::read_text(dir / "gmsh.log");
  const Mesh mesh = read_mesh(msh);
  validate_mesh(mesh);
  double volume = 0;
  for (int e = 0; e < mesh.num_tets(); ++e) volume += tet_volume(mesh, e);
  // 100 × 30 × 30 mm, in metres.
  EXPECT_NEAR(volume, 0.1 * 0.03 * 0.03, 1e-3 * 0.1 * 0.03 * 0.03);
  // Its extents, whichever axis the STL runs along.
  Eigen::Vector3d extent = mesh.nodes.rowwise().maxCoeff() - mesh.nodes.rowwise().minCoeff();
  std::sort(extent.data(), extent.data() + 3);
  EXPECT_NEAR(extent[0], 0.03, 1e-6);
  EXPECT_NEAR(extent[1], 0.03, 1e-6);
  EXPECT_NEAR(extent[2], 0.1, 1e-6);
  EXPECT_GT(mesh.num_tets(), 1000);  // 5 mm elements in a 100 × 30 × 30 mm box
}

}  // namespace kelvin
