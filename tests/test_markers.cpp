// Marker embedding: barycentric weights inside, projection just outside, errors far outside.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "base/error.hpp"
#include "engine/markers.hpp"
#include "engine/mesh.hpp"

using kelvin::Mesh;

namespace {

Mesh bar() {
  return kelvin::generate_box({0, 0, 0}, {0.02, 0.02, 0.1}, 0.01);
}

}  // namespace

TEST(Markers, InteriorPointsFollowAnAffineMapExactly) {
  const Mesh m = bar();
  Eigen::Matrix3Xd rest(3, 4);
  rest.col(0) << 0.013, 0.004, 0.071;
  rest.col(1) << 0.01, 0.01, 0.05;    // a shared node of many tets
  rest.col(2) << 0.0, 0.02, 0.1;      // a corner of the mesh
  rest.col(3) << 0.02, 0.007, 0.033;  // on the surface
  const auto mk = kelvin::embed_markers(m, {"a", "b", "c", "d"}, rest, 1e-3);
  ASSERT_EQ(mk.size(), 4u);
  for (const auto& e : mk) {
    EXPECT_GE(e.tet, 0);
    EXPECT_EQ(e.outside_distance, 0) << e.name;
    EXPECT_NEAR(e.weights.sum(), 1, 1e-14);
    EXPECT_GE(e.weights.minCoeff(), 0);
  }
  EXPECT_EQ(mk[0].name, "a");
  // Rest positions are reproduced.
  EXPECT_LT((kelvin::marker_positions(m, mk, m.nodes) - rest).norm(), 1e-15);

  // Under x = A X + b, linear tets map markers exactly by the same affine map.
  Eigen::Matrix3d A;
  A << 1.1, 0.2, -0.3, 0.05, 0.9, 0.1, -0.2, 0.3, 1.4;
  const Eigen::Vector3d b(0.01, -0.02, 0.5);
  const Eigen::Matrix3Xd x = (A * m.nodes).colwise() + b;
  const Eigen::Matrix3Xd expected = (A * rest).colwise() + b;
  EXPECT_LT((kelvin::marker_positions(m, mk, x) - expected).cwiseAbs().maxCoeff(), 1e-15);
}

TEST(Markers, SlightlyOutsideIsProjectedToTheSurface) {
  const Mesh m = bar();
  Eigen::Matrix3Xd rest(3, 2);
  rest.col(0) << 0.0123, -0.0004, 0.061;  // 0.4 mm outside face y = 0
  rest.col(1) << 0.0203, 0.0204, 0.1003;  // beyond the corner (0.02, 0.02, 0.1)
  const auto mk = kelvin::embed_markers(m, {"side", "corner"}, rest, 1e-3);
  EXPECT_NEAR(mk[0].outside_distance, 4e-4, 1e-15);
  EXPECT_NEAR(mk[1].outside_distance, std::sqrt(0.3 * 0.3 + 0.4 * 0.4 + 0.3 * 0.3) * 1e-3, 1e-15);
  const Eigen::Matrix3Xd p = kelvin::marker_positions(m, mk, m.nodes);
  EXPECT_LT((p.col(0) - Eigen::Vector3d(0.0123, 0, 0.061)).norm(), 1e-15);
  EXPECT_LT((p.col(1) - Eigen::Vector3d(0.02, 0.02, 0.1)).norm(), 1e-15);
  for (const auto& e : mk) {
    EXPECT_NEAR(e.weights.sum(), 1, 1e-14);
    EXPECT_GE(e.weights.minCoeff(), 0);
  }
}

TEST(Markers, FarOutsideThrowsNamingTheMarker) {
  const Mesh m = bar();
  Eigen::Matrix3Xd rest(3, 2);
  rest.col(0) << 0.01, 0.01, 0.05;
  rest.col(1) << 0.01, 0.01, 0.105;  // 5 mm above the top
  try {
    kelvin::embed_markers(m, {"ok", "tip"}, rest, 1e-3);
    FAIL() << "expected kelvin::Error";
  } catch (const kelvin::Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("marker 'tip'"), std::string::npos) << msg;
    EXPECT_NE(msg.find("is 5 mm outside the mesh (tolerance 1 mm)"), std::string::npos) << msg;
  }
}

TEST(Markers, SizeMismatchesAreErrors) {
  const Mesh m = bar();
  EXPECT_THROW(kelvin::embed_markers(m, {"a", "b"}, Eigen::Matrix3Xd::Zero(3, 1), 1e-3),
               kelvin::Error);
  const auto mk = kelvin::embed_markers(m, {"a"}, Eigen::Matrix3Xd::Constant(3, 1, 0.01), 1e-3);
  EXPECT_THROW(kelvin::marker_positions(m, mk, Eigen::Matrix3Xd::Zero(3, 2)), kelvin::Error);
}
