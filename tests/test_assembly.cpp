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

/// The mass matrix over the free dofs.
Eigen::SparseMatrix<double> mass_matrix(const FemModel& model) {
  return to_sparse_matrix(model.pattern(), model.mass());
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

  // The Schur-complement solver IDAS uses factorises the symmetric part of
  // S = K + c_j D + c_j² M (Cholesky): it solves exactly J with K replaced by
  // K − skew(S), skew(S) = (S − Sᵀ)/2 (the viscous stress's dependence on F), which
  // IDAS's Newton iteration takes as its approximate Newton matrix.
  SchurSolver schur(dae);
  ASSERT_TRUE(schur.assemble(t, cj, y.data()));
  ASSERT_TRUE(schur.factorize());
  EXPECT_FALSE(schur.factored_by_lu());
  const Eigen::SparseMatrix<double> S = J.bottomLeftCorner(n, n) +
                                        cj * (J.bottomRightCorner(n, n) - cj * mass_matrix(model)) +
                                        cj * cj * mass_matrix(model);
  const Eigen::SparseMatrix<double> skew = 0.5 * (S - Eigen::SparseMatrix<double>(S.transpose()));
  ASSERT_GT(skew.norm(), 1e-8 * S.norm()) << "S is symmetric here: the case tests nothing";
  Eigen::SparseMatrix<double> J_sym = J;
  for (int c = 0; c < n; ++c)
    for (Eigen::SparseMatrix<double>::InnerIterator it(skew, c); it; ++it)
      J_sym.coeffRef(n + it.row(), c) -= it.value();
  const Eigen::VectorXd b = random(N, 1.0);
  Eigen::VectorXd x(N);
  schur.solve(b.data(), x.data());
  EXPECT_LT((J_sym * x - b).norm() / b.norm(), 1e-10);
  // The adjoint's solve, with c_B = −c_j: x₂ from sym(S) x₂ = c_B b₂ − b₁ (Sᵀ's
  // symmetric part is S's), then x₁ = (b₁ + Kᵀ x₂) / c_B, the first row exactly.
  schur.solve_adjoint(b.data(), x.data());
  const Eigen::SparseMatrix<double> S_sym = S - skew;
  const Eigen::SparseMatrix<double> Kt = J.bottomLeftCorner(n, n).transpose();
  const Eigen::VectorXd x2 = x.tail(n), rhs2 = -cj * b.tail(n) - b.head(n);
  EXPECT_LT((S_sym * x2 - rhs2).norm() / rhs2.norm(), 1e-10);
  EXPECT_LT((-cj * x.head(n) - Kt * x2 - b.head(n)).norm() / b.head(n).norm(), 1e-10);
}

// Where S's symmetric part is not positive definite (here: a slender bar squeezed
// to 60 % of its length, far past buckling, at a tiny c_j) KLU factorises S itself
// and the solve is exactly the Newton matrix's.
// The closed-form product that mass-proportional damping uses is the element mass
// matrix's, lumped and consistent.
TEST(ElementMass, ClosedFormProductMatchesTheMatrix) {
  const Mesh mesh = generate_box({0, 0, 0}, {0.03, 0.02, 0.01}, 0.01);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u01(500, 1500);
  Eigen::VectorXd rho(mesh.num_tets());
  for (auto& r : rho) r = u01(rng);
  for (bool lumped : {false, true}) {
    const FemModel model(mesh, materials(mesh.num_tets(), false), rho, {0, 0, -9.81}, {}, lumped);
    for (int e = 0; e < mesh.num_tets(); e += 5) {
      const Eigen::Matrix<double, 3, 4> v = Eigen::Matrix<double, 3, 4>::Random();
      const Eigen::Matrix<double, 12, 1> expected = model.element_mass(e) * v.reshaped();
      const Eigen::Matrix<double, 12, 1> got = model.element_mass_times(e, v).reshaped();
      EXPECT_LT((got - expected).norm(), 1e-14 * expected.norm()) << "element " << e;
    }
  }
}

TEST(SchurSolver, AnIndefiniteNewtonMatrixFallsBackToLU) {
  Mesh mesh = generate_box({0, 0, 0}, {0.2, 0.01, 0.01}, 0.005);
  NodeSelection sel;
  sel.axis = 0;
  sel.at = 0;
  FemModel model(mesh, materials(mesh.num_tets(), true),
                 Eigen::VectorXd::Constant(mesh.num_tets(), 900), {0, 0, 0},
                 {{"base", select_nodes(mesh, sel), std::make_shared<FixedMotion>()}}, true);
  DaeSystem dae(model);
  const int n = model.num_dofs(), N = dae.size();
  Eigen::Matrix3Xd squeezed = mesh.nodes;
  squeezed.row(0) *= 0.6;
  Eigen::VectorXd y = Eigen::VectorXd::Zero(N);
  model.restrict(squeezed, y.data());
  const double cj = 1e-3;
  const Eigen::SparseMatrix<double> J = newton_matrix(dae, 0, cj, y);
  SchurSolver schur(dae);
  ASSERT_TRUE(schur.assemble(0, cj, y.data()));
  ASSERT_TRUE(schur.factorize());
  EXPECT_TRUE(schur.factored_by_lu());
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::VectorXd b(N), x(N);
  for (auto& v : b) v = u(rng);
  schur.solve(b.data(), x.data());
  EXPECT_LT((J * x - b).norm() / b.norm(), 1e-8);
  (void)n;
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
