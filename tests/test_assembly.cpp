// Global assembly: the IDAS Newton matrix against finite differences of the
// residual, the patch test, and rigid-motion invariance of internal forces.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/SparseCore>
#include <random>

#include "engine/dae_system.hpp"
#include "engine/fem_model.hpp"
#include "engine/mesh.hpp"
#include "engine/schur_solver.hpp"
#include "engine/selection.hpp"
#include "engine/static_solver.hpp"

using namespace kelvin;

namespace {

std::vector<MaterialTerm> materials(int ne, bool viscous, double h_index = 0.7) {
  std::vector<MaterialTerm> t;
  Eigen::Vector2d lame(3e4, 1e4);
  t.push_back({create_builtin_material("neo-hookean"), lame.replicate(1, ne), {}});
  if (viscous)
    t.push_back(
        {create_builtin_material("power-law"), Eigen::Vector2d(5.0, h_index).replicate(1, ne), {}});
  return t;
}

/// A "pose" whose R is any matrix: x = A X + b imposes a homogeneous deformation.
class AffineMotion : public RigidMotion {
 public:
  AffineMotion(Eigen::Matrix3d A, Eigen::Vector3d b) { pose_.R = A, pose_.d = b; }
  RigidPose at(double) const override { return pose_; }

 private:
  RigidPose pose_;
};

std::vector<int> boundary_nodes(const Mesh& mesh) {
  const Eigen::Vector3d lo = mesh.nodes.rowwise().minCoeff(), hi = mesh.nodes.rowwise().maxCoeff();
  std::vector<int> ids;
  for (int a = 0; a < mesh.num_nodes(); ++a) {
    const Eigen::Vector3d X = mesh.nodes.col(a);
    if (((X - lo).array().abs() < 1e-12).any() || ((X - hi).array().abs() < 1e-12).any())
      ids.push_back(a);
  }
  return ids;
}

Eigen::SparseMatrix<double> newton_matrix(DaeSystem& dae, double t, double cj,
                                          const Eigen::VectorXd& y) {
  std::vector<int> colptr(dae.size() + 1), rowind(dae.nnz());
  std::vector<double> val(dae.nnz());
  dae.structure(colptr.data(), rowind.data());
  EXPECT_TRUE(dae.jacobian(t, cj, y.data(), val.data()));
  return Eigen::Map<Eigen::SparseMatrix<double>>(dae.size(), dae.size(), dae.nnz(), colptr.data(),
                                                 rowind.data(), val.data());
}

}  // namespace

class JacobianTest : public ::testing::TestWithParam<bool> {};

TEST_P(JacobianTest, NewtonMatrixMatchesFiniteDifferencesOfTheResidual) {
  const bool lumped = GetParam();
  Mesh mesh = generate_box({0, 0, 0}, {0.06, 0.02, 0.02}, 0.01);
  NodeSelection sel;
  sel.axis = 0;
  sel.at = 0;
  auto motion = std::make_shared<SinusoidMotion>(
      std::vector<Sinusoid>{{0.003, 7, 0.3, Eigen::Vector3d::UnitY()}},
      std::vector<Sinusoid>{{0.2, 5, 0.1}}, Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero());
  FemModel model(mesh, materials(mesh.num_tets(), true),
                 Eigen::VectorXd::Constant(mesh.num_tets(), 900), {0, 0, -9.81},
                 {{"base", select_nodes(mesh, sel), motion}}, lumped);
  DaeSystem dae(model);
  const int n = model.num_dofs(), N = dae.size();

  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  auto random = [&](int size, double s) {
    Eigen::VectorXd v(size);
    for (auto& x : v) x = s * u(rng);
    return v;
  };
  const double t = 0.013, cj = 350.0;
  Eigen::VectorXd y(N), yp = random(N, 0.1);
  Eigen::Matrix3Xd rest = mesh.nodes;
  model.restrict(rest, y.data());
  y.head(n) += random(n, 5e-4);
  y.tail(n) = random(n, 0.05);

  const Eigen::SparseMatrix<double> J = newton_matrix(dae, t, cj, y);
  // Directional derivative along (δ, c_j δ): exactly J δ for F(y + εδ, y' + ε c_j δ).
  for (int trial = 0; trial < 3; ++trial) {
    const Eigen::VectorXd d = random(N, 1.0);
    const Eigen::VectorXd Jd = J * d;
    double best = INFINITY;
    for (double eps : {1e-5, 1e-6, 1e-7, 1e-8}) {
      Eigen::VectorXd rp(N), rm(N);
      const Eigen::VectorXd yp1 = y + eps * d, ypp1 = yp + eps * cj * d;
      const Eigen::VectorXd ym1 = y - eps * d, ypm1 = yp - eps * cj * d;
      ASSERT_TRUE(dae.residual(t, yp1.data(), ypp1.data(), rp.data()));
      ASSERT_TRUE(dae.residual(t, ym1.data(), ypm1.data(), rm.data()));
      best = std::min(best, ((rp - rm) / (2 * eps) - Jd).norm() / Jd.norm());
    }
    EXPECT_LT(best, 1e-6) << "trial " << trial;
  }

  // The Schur-complement solver IDAS uses solves exactly this matrix.
  SchurSolver schur(dae);
  ASSERT_TRUE(schur.assemble(t, cj, y.data()));
  ASSERT_TRUE(schur.factorize());
  const Eigen::VectorXd b = random(N, 1.0);
  Eigen::VectorXd x(N);
  schur.solve(b.data(), x.data());
  EXPECT_LT((J * x - b).norm() / b.norm(), 1e-10);
}

INSTANTIATE_TEST_SUITE_P(LumpedAndConsistentMass, JacobianTest, ::testing::Values(true, false));

TEST(PatchTest, HomogeneousDeformationIsReproducedInside) {
  Mesh mesh = generate_box({0, 0, 0}, {0.04, 0.03, 0.03}, 0.01);
  const std::vector<int> boundary = boundary_nodes(mesh);
  ASSERT_LT(static_cast<int>(boundary.size()), mesh.num_nodes());  // there are interior nodes
  Eigen::Matrix3d A;
  A << 1.15, 0.08, -0.05, 0.03, 0.9, 0.1, -0.06, 0.02, 1.05;
  const Eigen::Vector3d b(0.01, -0.02, 0.005);
  FemModel model(mesh, materials(mesh.num_tets(), false),
                 Eigen::VectorXd::Constant(mesh.num_tets(), 1000), Eigen::Vector3d::Zero(),
                 {{"boundary", boundary, std::make_shared<AffineMotion>(A, b)}}, true);

  // Start from the exact field with interior nodes scattered by up to 1.5 mm (15%
  // of the element size): Newton must find its way back to the affine field.
  Eigen::Matrix3Xd start = (A * mesh.nodes).colwise() + b;
  start += 1.5e-3 * Eigen::Matrix3Xd::Random(3, mesh.num_nodes());
  Eigen::VectorXd x(model.num_dofs());
  model.restrict(start, x.data());
  const StaticResult r = solve_static(model, 0.0, x);
  ASSERT_TRUE(r.converged) << r.message;
  Eigen::Matrix3Xd full, vel;
  model.expand(0.0, x.data(), nullptr, full, vel);
  for (int a = 0; a < mesh.num_nodes(); ++a)
    EXPECT_LT((full.col(a) - (A * mesh.nodes.col(a) + b)).norm(), 1e-12) << "node " << a;
}

TEST(RigidMotion, InternalForcesVanishUnderRigidMotion) {
  Mesh mesh = generate_box({0, 0, 0}, {0.08, 0.02, 0.03}, 0.01);
  NodeSelection sel;
  sel.axis = 0;
  sel.at = 0;
  // A large rotation about a tilted axis plus a translation, with non-zero rates.
  auto motion = std::make_shared<SinusoidMotion>(
      std::vector<Sinusoid>{{0.05, 3, 0.4, Eigen::Vector3d(1, 2, 2).normalized()}},
      std::vector<Sinusoid>{{1.2, 2, 0.9}}, Eigen::Vector3d(1, -1, 2).normalized(),
      Eigen::Vector3d(0.01, 0.02, -0.01));
  FemModel model(mesh, materials(mesh.num_tets(), true),
                 Eigen::VectorXd::Constant(mesh.num_tets(), 1000), Eigen::Vector3d::Zero(),
                 {{"base", select_nodes(mesh, sel), motion}}, true);
  for (double t : {0.0, 0.11, 0.37}) {
    const RigidPose pose = motion->at(t);
    Eigen::Matrix3Xd x(3, mesh.num_nodes()), v(3, mesh.num_nodes());
    for (int a = 0; a < mesh.num_nodes(); ++a) {
      x.col(a) = pose.position(mesh.nodes.col(a));
      v.col(a) = pose.velocity(mesh.nodes.col(a));
    }
    AssemblyOutput out;
    ASSERT_TRUE(model.assemble(x, v, {}, out));
    // Scale: the individual terms that must cancel, μ |F| on one element face
    // (≈ 1e4 Pa × 1e-4 m²); the residual must be at the level of round-off.
    const double scale = 1e4 * 1e-4;
    EXPECT_LT(out.force.norm(), 1e-11 * scale) << "t = " << t;
  }
}
