// A time step allocates no memory once the integrator is warm: residuals, Newton
// matrices, factorisations and solves reuse their workspaces (counted through the
// global operator new of this test binary).
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>

#include "engine/fem_model.hpp"
#include "engine/idas_integrator.hpp"
#include "engine/mesh.hpp"
#include "engine/rigid_motion.hpp"
#include "engine/selection.hpp"

// GCC cannot see that this file's operator new and delete are a malloc/free pair.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

namespace {
std::atomic<bool> counting{false};
std::atomic<long> allocations{0};
}  // namespace

void* operator new(std::size_t size) {
  if (counting) ++allocations;
  if (void* p = std::malloc(size ? size : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept {
  std::free(p);
}
void operator delete(void* p, std::size_t) noexcept {
  std::free(p);
}

namespace kelvin {

TEST(StepAllocations, WarmStepsAllocateNothing) {
  const Mesh mesh = generate_box({0, 0, 0}, {0.1, 0.02, 0.02}, 0.01);
  const int ne = mesh.num_tets();
  NodeSelection root;
  root.axis = 0;
  root.at = 0;
  Sinusoid shake;
  shake.amplitude = 0.004;
  shake.frequency = 10;
  shake.direction = Eigen::Vector3d::UnitY();
  // Lumped, consistent, and consistent with internal variables: a relaxing branch and
  // one at g = 0 (a screened candidate: its strains evolve, it loads nothing).
  for (int config : {0, 1, 2}) {
    const bool lumped = config == 0;
    std::vector<MaterialTerm> terms;
    terms.push_back(
        {create_builtin_material("neo-hookean"), Eigen::Vector2d(5e5, 3e5).replicate(1, ne), {}});
    terms.push_back(
        {create_builtin_material("power-law"), Eigen::Vector2d(5.0, 0.9).replicate(1, ne), {}});
    if (config == 2)
      for (double g : {2e5, 0.0})
        terms.push_back(
            {create_builtin_material("maxwell"), Eigen::Vector2d(g, 0.02).replicate(1, ne), {}});
    std::vector<ClampBinding> clamps = {
        {"root", select_nodes(mesh, root),
         std::make_shared<SinusoidMotion>(std::vector<Sinusoid>{shake}, std::vector<Sinusoid>{},
                                          Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero())}};
    FemModel model(mesh, std::move(terms), Eigen::VectorXd::Constant(ne, 1000.0),
                   Eigen::Vector3d(0, 0, -9.81), std::move(clamps), lumped);
    IntegratorOptions opt;
    opt.rtol = 1e-4;
    opt.atol = 1e-9;
    IdasIntegrator ida(model, opt);
    Eigen::VectorXd x0(model.num_dofs());
    model.restrict(mesh.nodes, x0.data());
    ida.initialize(0.0, x0, Eigen::VectorXd::Zero(x0.size()));
    ASSERT_TRUE(ida.advance_to(0.02, 1.0)) << ida.error();  // warm: every workspace sized
    const IntegratorStats before = ida.stats();
    allocations = 0;
    counting = true;
    const bool ok = ida.advance_to(0.2, 1.0);
    counting = false;
    ASSERT_TRUE(ok) << ida.error();
    const IntegratorStats after = ida.stats();
    EXPECT_GT(after.steps - before.steps, 50) << "configuration " << config;
    if (config == 2) EXPECT_GT(model.num_internal(), 0);
    EXPECT_GT(after.jacobian_evals, before.jacobian_evals) << "configuration " << config;
    EXPECT_EQ(allocations.load(), 0) << "configuration " << config;
  }
}

}  // namespace kelvin
