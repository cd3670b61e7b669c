// The element loops on several threads give the one-thread results exactly: the
// residual, the Newton matrix's K and D, the adjoint's Kᵀλ and Dᵀλ, and a whole
// IDAS trajectory (same steps, same positions bit for bit).
#include <gtest/gtest.h>

#include <random>

#include "engine/dae_system.hpp"
#include "engine/fem_model.hpp"
#include "engine/idas_integrator.hpp"
#include "engine/mesh.hpp"
#include "engine/rigid_motion.hpp"
#include "engine/selection.hpp"
#include "engine/threads.hpp"

using namespace kelvin;

namespace {

/// Restores the thread count a test changed.
struct Threads {
  int saved = thread_count();
  ~Threads() { set_threads(saved); }
};

/// A 1500-tet bar, clamped at z = 0 and shaken, neo-Hookean + Newtonian viscosity:
/// enough elements for the loops to run in parallel.
struct Bar {
  Mesh mesh = generate_box({0, 0, 0}, {0.02, 0.02, 0.2}, 0.0067);
  std::unique_ptr<FemModel> model;
  Bar() {
    const int ne = mesh.num_tets();
    std::vector<MaterialTerm> terms;
    terms.push_back({create_builtin_material("neo-hookean"),
                     Eigen::Vector2d(1.2e4, 1.5e5).replicate(1, ne),
                     {}});
    terms.push_back(
        {create_builtin_material("power-law"), Eigen::Vector2d(0.5, 1.0).replicate(1, ne), {}});
    NodeSelection top;
    top.kind = NodeSelection::Kind::Plane;
    top.axis = 2;
    top.at = 0.0;
    Sinusoid shake;
    shake.amplitude = 0.008;
    shake.frequency = 3;
    shake.phase = -M_PI / 2;
    std::vector<ClampBinding> clamps = {
        {"top", select_nodes(mesh, top),
         std::make_shared<SinusoidMotion>(std::vector<Sinusoid>{shake}, std::vector<Sinusoid>{},
                                          Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero())}};
    model = std::make_unique<FemModel>(mesh, std::move(terms), Eigen::VectorXd::Constant(ne, 100.0),
                                       Eigen::Vector3d(0, 0, -9.81), std::move(clamps), false);
  }
  /// A deformed, moving state over the free dofs.
  Eigen::VectorXd state(unsigned seed) const {
    const int n = model->num_dofs();
    Eigen::VectorXd y(2 * n);
    model->restrict(mesh.nodes, y.data());
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(-1, 1);
    for (int i = 0; i < n; ++i) y[i] += 2e-4 * u(rng);
    for (int i = n; i < 2 * n; ++i) y[i] = 0.05 * u(rng);
    return y;
  }
};

}  // namespace

TEST(Threads, ResidualNewtonMatrixAndAdjointProductsAreExactlyTheOneThreadResults) {
  Threads restore;
  Bar bar;
  ASSERT_GE(bar.mesh.num_tets(), 1000);
  const int n = bar.model->num_dofs();
  const Eigen::VectorXd y = bar.state(7);
  Eigen::VectorXd yp = Eigen::VectorXd::Zero(2 * n), lambda = bar.state(8).head(n);

  struct Result {
    Eigen::VectorXd r, kt, dt;
    std::vector<double> K, D, K_from_tangents;
  };
  auto evaluate = [&](int threads) {
    set_threads(threads);
    DaeSystem dae(*bar.model);
    Result out;
    out.r.resize(2 * n);
    EXPECT_TRUE(dae.residual(0.1, y.data(), yp.data(), out.r.data()));
    EXPECT_TRUE(dae.stiffness_and_damping(0.1, y.data()));
    out.K = dae.last_assembly().K;
    out.D = dae.last_assembly().D;
    EXPECT_TRUE(dae.element_tangents(0.1, y.data(), true));
    dae.assemble_from_tangents();
    out.K_from_tangents = dae.last_assembly().K;
    ElementSlots slots;
    out.kt.resize(n);
    out.dt.resize(n);
    bar.model->transpose_multiply(dae.tangents(), lambda.data(), out.kt.data(), out.dt.data(),
                                  slots);
    return out;
  };
  const Result one = evaluate(1), two = evaluate(2), three = evaluate(3);
  for (const Result* other : {&two, &three}) {
    EXPECT_EQ(one.r, other->r);
    EXPECT_EQ(one.K, other->K);
    EXPECT_EQ(one.D, other->D);
    EXPECT_EQ(one.K_from_tangents, other->K_from_tangents);
    EXPECT_EQ(one.kt, other->kt);
    EXPECT_EQ(one.dt, other->dt);
  }
  // Not trivially equal: the state is deformed and moving.
  EXPECT_GT(one.r.tail(n).norm(), 0);
  EXPECT_GT(one.dt.norm(), 0);
}

TEST(Threads, TheFirstInadmissibleElementIsReportedWhateverTheThreadCount) {
  Threads restore;
  Bar bar;
  const int n = bar.model->num_dofs();
  Eigen::VectorXd y = bar.state(3), yp = Eigen::VectorXd::Zero(2 * n), r(2 * n);
  // Invert two elements far apart: push one node of each through its opposite face.
  Eigen::Matrix3Xd x = bar.mesh.nodes;
  const std::vector<int> inverted = {200, 1300};
  for (int e : inverted) {
    const auto& el = bar.model->elements()[e];
    int node = -1;
    for (int a = 0; a < 4 && node < 0; ++a)
      if (bar.model->dof(el.nodes[a], 0) >= 0) node = el.nodes[a];
    ASSERT_GE(node, 0);
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (int a = 0; a < 4; ++a) centroid += bar.mesh.nodes.col(el.nodes[a]) / 4;
    x.col(node) += 3.0 * (centroid - bar.mesh.nodes.col(node));
  }
  bar.model->restrict(x, y.data());
  int first[3] = {};
  for (int threads = 1; threads <= 3; ++threads) {
    set_threads(threads);
    DaeSystem dae(*bar.model);
    EXPECT_FALSE(dae.residual(0, y.data(), yp.data(), r.data()));
    first[threads - 1] = dae.last_assembly().failed_element;
  }
  EXPECT_GE(first[0], 0);
  EXPECT_LE(first[0], inverted[0]);  // moving a node may invert a neighbour first
  EXPECT_EQ(first[0], first[1]);
  EXPECT_EQ(first[0], first[2]);
}

TEST(Threads, AWholeTrajectoryIsTheOneThreadTrajectory) {
  Threads restore;
  Bar bar;
  const int n = bar.model->num_dofs();
  auto run = [&](int threads) {
    set_threads(threads);
    IntegratorOptions opt;
    opt.rtol = 1e-4;
    opt.atol = 1e-6;  // released from rest: the kHz modes carry no more than this
    opt.max_order = 2;
    IdasIntegrator ida(*bar.model, opt);
    Eigen::VectorXd x0(n);
    bar.model->restrict(bar.mesh.nodes, x0.data());
    ida.initialize(0.0, x0, Eigen::VectorXd::Zero(n));
    EXPECT_TRUE(ida.advance_to(0.02, 0.02)) << ida.error();
    return std::make_pair(ida.stats().steps, Eigen::VectorXd(ida.positions()));
  };
  const auto one = run(1), two = run(2);
  EXPECT_GT(one.first, 50);
  EXPECT_EQ(one.first, two.first);
  EXPECT_EQ(one.second, two.second);
}
