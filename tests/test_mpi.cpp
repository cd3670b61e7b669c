// FitProblem across MPI ranks (run by ctest under mpirun -np 2): each rank simulates
// the experiments it owns, and every rank ends up with what a serial evaluation on
// one rank gives, to the bit — Φ, ∇Φ, the Gauss–Newton rows, and a whole fit's path.
#include <gtest/gtest.h>

#include "adjoint/fit_problem.hpp"
#include "adjoint/uncertainty.hpp"
#include "base/spread_tasks.hpp"
#include "fit/fit_loop.hpp"
#include "mpi_fixture.hpp"
#include "parallel/mpi_communicator.hpp"

namespace kelvin {
std::atomic<bool> g_interrupted{false};  // what SIGINT would set; the communicator's too
namespace {

/// The three-motion fit, loaded twice on this rank: spread over the ranks and alone.
struct Problems {
  Scenario scenario;
  std::unique_ptr<FitProblem> spread, alone;
};

Problems load(const std::string& name, const std::string& fit_keys,
              const std::string& solver_keys = "") {
  // Each rank writes its own files: they are identical, and no rank waits for another.
  const test::fs::path dir = test::scratch(fmt::format("{}-rank{}", name, world().rank()));
  Problems p;
  p.scenario = load_scenario(test::write_three_motion_fit(dir, fit_keys, solver_keys));
  p.spread = std::make_unique<FitProblem>(p.scenario, p.scenario.fit.parameters, world());
  p.alone =
      std::make_unique<FitProblem>(p.scenario, p.scenario.fit.parameters, serial_communicator());
  return p;
}

TEST(Mpi, TheTestRunsOnTwoRanks) {
  ASSERT_EQ(world().size(), 2);
}

TEST(Mpi, AnEvaluationOnTwoRanksIsTheSerialOneBitForBit) {
  Problems p = load("mpi-evaluate", "");
  ASSERT_EQ(p.spread->num_experiments(), 3);
  EXPECT_TRUE(p.spread->owns(world().rank()));
  EXPECT_FALSE(p.spread->owns(1 - world().rank()));
  for (GradientMethod method : {GradientMethod::kAdjoint, GradientMethod::kForward}) {
    GradientOptions o;
    o.method = method;
    const Eigen::VectorXd x = p.spread->map().initial();
    const Evaluation a = p.spread->evaluate(x, o), b = p.alone->evaluate(x, o);
    ASSERT_TRUE(a.ok) << a.error;
    ASSERT_TRUE(b.ok) << b.error;
    EXPECT_EQ(a.phi, b.phi);
    EXPECT_EQ(a.rms, b.rms);
    ASSERT_EQ(a.gradient.size(), 2);
    EXPECT_EQ(a.gradient, b.gradient);
    EXPECT_GT(a.gradient.norm(), 0);
    ASSERT_EQ(a.experiments.size(), 3u);
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(a.experiments[k].phi_per_marker, b.experiments[k].phi_per_marker) << k;
      EXPECT_EQ(a.experiments[k].gradient, b.experiments[k].gradient) << k;
      EXPECT_EQ(a.experiments[k].forward_stats.steps, b.experiments[k].forward_stats.steps) << k;
      // Each rank holds every experiment's plan as its owner left it.
      EXPECT_EQ(p.spread->plan(k).order_choice().max_order,
                p.alone->plan(k).order_choice().max_order)
          << k;
    }
    // After the first evaluation the ranks are balanced by its costs: the costliest
    // motion alone on rank 0, the other two on rank 1. Whichever that is, one motion
    // changed hands from i mod 2, and the second evaluation (forward) still matches.
    if (method != GradientMethod::kAdjoint) continue;
    int costliest = 0;
    for (int k = 1; k < 3; ++k)
      if (a.experiments[k].seconds > a.experiments[costliest].seconds) costliest = k;
    for (int k = 0; k < 3; ++k) EXPECT_EQ(p.spread->owner(k), k == costliest ? 0 : 1) << k;
  }
}

TEST(Mpi, TheGaussNewtonRowsOnTwoRanksAreTheSerialOnes) {
  Problems p = load("mpi-gauss-newton", "");
  const Eigen::VectorXd x = p.spread->map().initial();
  // After an evaluation the owners are balanced (no longer i mod 2): the rows travel
  // by them.
  GradientOptions plain;
  plain.method = GradientMethod::kNone;
  ASSERT_TRUE(p.spread->evaluate(x, plain).ok);
  ASSERT_TRUE(p.alone->evaluate(x, plain).ok);
  const GaussNewtonSystem a = gauss_newton_system(*p.spread, x),
                          b = gauss_newton_system(*p.alone, x);
  ASSERT_TRUE(a.ok) << a.error;
  ASSERT_TRUE(b.ok) << b.error;
  ASSERT_GT(a.residual.size(), 100);
  EXPECT_EQ(a.residual, b.residual);
  EXPECT_EQ(a.jacobian, b.jacobian);
  ASSERT_EQ(a.samples.size(), b.samples.size());
  for (size_t i = 0; i < a.samples.size(); ++i) {
    EXPECT_EQ(a.samples[i].experiment, b.samples[i].experiment);
    EXPECT_EQ(a.samples[i].t, b.samples[i].t);
  }
}

TEST(Mpi, AJointFitOnTwoRanksTakesTheSerialFitsPath) {
  Problems p = load("mpi-fit", "  max_evaluations: 12\n");
  const FitOptions o = fit_options_of(p.scenario);
  const FitOutcome a = run_fit(*p.spread, p.spread->map().initial(), o);
  const FitOutcome b = run_fit(*p.alone, p.alone->map().initial(), o);
  ASSERT_EQ(a.history.size(), 12u);
  ASSERT_EQ(a.history.size(), b.history.size());
  for (size_t i = 0; i < a.history.size(); ++i) {
    EXPECT_EQ(a.history[i].objective, b.history[i].objective) << i;
    EXPECT_EQ(a.history[i].accepted, b.history[i].accepted) << i;
  }
  EXPECT_EQ(a.p, b.p);
  EXPECT_EQ(a.stop_reason, b.stop_reason);
  // A path that goes somewhere: μ, 1.6× off at the start, is within 1 % after 12.
  EXPECT_NEAR(p.spread->map().value(a.p, 0), 3.0e5, 1e-2 * 3.0e5);
}

TEST(Mpi, ASimulationFailingOnOneRankFailsTheEvaluationOnBoth) {
  // Motion 1 (rank 1's) is allowed 20 steps: its run fails, the others' do not.
  Problems p = load("mpi-failure", "", ", max_steps: 20");
  GradientOptions o;
  o.method = GradientMethod::kAdjoint;
  const Evaluation a = p.spread->evaluate(p.spread->map().initial(), o);
  const Evaluation b = p.alone->evaluate(p.alone->map().initial(), o);
  EXPECT_FALSE(a.ok);
  EXPECT_FALSE(b.ok);
  EXPECT_EQ(a.error, b.error);
  EXPECT_NE(a.error.find("motion1.yaml"), std::string::npos) << a.error;
  EXPECT_TRUE(a.experiments[0].ok);
  EXPECT_FALSE(a.experiments[1].ok);
  EXPECT_TRUE(a.experiments[2].ok);
}

TEST(Mpi, AnInterruptOnOneRankStopsTheEvaluationOnBoth) {
  Problems p = load("mpi-interrupt", "");
  // Only rank 1 receives the signal (before its run: its experiment stops at once).
  g_interrupted = world().rank() == 1;
  GradientOptions o;
  o.method = GradientMethod::kNone;
  o.interrupt = &g_interrupted;
  const Evaluation ev = p.spread->evaluate(p.spread->map().initial(), o);
  EXPECT_TRUE(ev.interrupted);
  EXPECT_TRUE(g_interrupted);  // rank 0's flag, raised through Communicator::interrupt
  EXPECT_FALSE(ev.ok);
  g_interrupted = false;
}

// Tasks 0..4 on two ranks: 0, 2, 4 on rank 0, 1 and 3 on rank 1; each rank gets all
// five results in task order, and rank 0 prints rank 1's lines once they arrive.
TEST(Mpi, SpreadTasksGiveEveryRankEveryResultInTaskOrder) {
  std::vector<int> ran;
  std::vector<std::string> printed;
  const std::vector<std::string> results = spread_tasks(
      world(), 5,
      [&](int k, const ProgressLine& say) {
        ran.push_back(k);
        say(fmt::format("task {} on rank {}", k, world().rank()));
        return fmt::format("result {}", k);
      },
      [&](const std::string& line) { printed.push_back(line); }, nullptr);
  ASSERT_EQ(results.size(), 5u);
  for (int k = 0; k < 5; ++k) EXPECT_EQ(results[k], fmt::format("result {}", k));
  EXPECT_EQ(ran, world().root() ? std::vector<int>({0, 2, 4}) : std::vector<int>({1, 3}));
  if (world().root())
    EXPECT_EQ(printed,
              std::vector<std::string>({"task 0 on rank 0", "task 2 on rank 0", "task 4 on rank 0",
                                        "task 1 on rank 1", "task 3 on rank 1"}));
  else
    EXPECT_TRUE(printed.empty());
}

// Measured costs (V09's screening runs, in seconds) put the costliest first on the
// least loaded rank: 611 s split 306/305 where round robin gives 372/239. With one
// cost unknown, round robin.
TEST(Mpi, TasksOfKnownCostAreBalancedCostliestFirst) {
  const std::vector<double> costs = {40, 25, 16, 19, 28, 24, 70, 161, 218};
  const std::vector<int> ranks = task_ranks(costs, 2);
  double load[2] = {0, 0};
  for (std::size_t k = 0; k < costs.size(); ++k) load[ranks[k]] += costs[k];
  EXPECT_EQ(ranks[8], 0);  // the costliest
  EXPECT_EQ(ranks[7], 1);
  EXPECT_LE(std::max(load[0], load[1]), 306.0);
  std::vector<double> unknown = costs;
  unknown[3] = 0;
  EXPECT_EQ(task_ranks(unknown, 2), std::vector<int>({0, 1, 0, 1, 0, 1, 0, 1, 0}));
  // spread_tasks runs each task where it is told to.
  std::vector<int> ran;
  const std::vector<std::string> results = spread_tasks(
      world(), 9,
      [&](int k, const ProgressLine&) {
        ran.push_back(k);
        return std::to_string(k);
      },
      nullptr, nullptr, ranks);
  for (int k = 0; k < 9; ++k) EXPECT_EQ(results[k], std::to_string(k));
  for (int k : ran) EXPECT_EQ(ranks[k], world().rank()) << k;
}

// Task 1 (rank 1) throws: both ranks throw its message, and rank 1 runs none of its
// later tasks (a serial run would have stopped there).
TEST(Mpi, ATaskThatThrowsOnOneRankEndsBothWithItsMessage) {
  std::vector<int> ran;
  std::string message;
  try {
    spread_tasks(
        world(), 4,
        [&](int k, const ProgressLine&) {
          ran.push_back(k);
          if (k == 1) throw Error("motion1.yaml: cannot read");
          return std::string();
        },
        nullptr, nullptr);
  } catch (const Error& e) {
    message = e.what();
  }
  EXPECT_EQ(message, "motion1.yaml: cannot read");
  EXPECT_EQ(ran, world().root() ? std::vector<int>({0, 2}) : std::vector<int>({1}));
}

// An interrupt that reaches rank 1 alone during the tasks is raised on rank 0 too, and
// the agreed check says so on both.
TEST(Mpi, AnInterruptDuringTheTasksOfOneRankIsRaisedOnBoth) {
  g_interrupted = false;
  spread_tasks(
      world(), 2,
      [&](int k, const ProgressLine&) {
        if (k == 1) g_interrupted = true;
        return std::string();
      },
      nullptr, &g_interrupted);
  EXPECT_TRUE(g_interrupted.load());
  EXPECT_TRUE(any_interrupted(world(), g_interrupted.load()));
  g_interrupted = false;
  // Set on rank 1 only, between collectives: the agreed check raises it on rank 0.
  if (!world().root()) g_interrupted = true;
  EXPECT_TRUE(any_interrupted(world(), g_interrupted.load()));
  EXPECT_TRUE(g_interrupted.load());
  g_interrupted = false;
}

}  // namespace
}  // namespace kelvin

int main(int argc, char** argv) {
  kelvin::MpiRuntime mpi(argc, argv);
  kelvin::MpiCommunicator comm(&kelvin::g_interrupted);
  kelvin::set_world(&comm);
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();  // mpirun fails when either rank does
}
