// Cost and memory of gradients on the bundled foam cylinder, with observed tracks
// simulated from the example's parameters and a start 30% off.
//
// Cost: wall time of Φ + adjoint gradient over Φ alone, for 4 global parameters,
// ~100 region parameters (slabs along the axis) and one parameter per element;
// forward sensitivities for comparison (their cost grows with the count).
// Memory: peak resident memory of one evaluation (each in a forked child, so the
// peaks do not mix) for 1×, 10×, 100× the base duration: Φ alone (one run, no
// segments), the adjoint with its default automatic segments, and with segments of
// a given length.
//
//   build/bin/bench_gradient [--h 0.01] [--duration 0.1] [--repeat 3]
//                            [--regions 100] [--memory-base 0.05] [--segment 0.05]
//                            [--skip-cost] [--skip-memory] [--fsa-max 100]
//                            [--memory-factors 1,10,100] [--checkpoint-steps N]
// --checkpoint-steps: the cost table's checkpoint budget (GradientOptions); 0 = default.
// --fsa-max: forward sensitivities are timed only for maps with at most this many
// parameters (their cost grows with the count; at ≥ 8k tets 100 of them take hours).
#include <fmt/format.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "adjoint/fit_problem.hpp"
#include "base/error.hpp"
#include "bench/foam_cylinder.hpp"
#include "yaml/scenario_simulation.hpp"

using namespace kelvin;

namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

/// Runs `job` in a child process and returns its wait status and resource use.
/// The memory figures need a process per measurement; and no process may fork
/// after CHOLMOD has started libgomp's thread pool (the child would wait forever
/// on a lock held by a thread it does not have), so the truth simulation of the
/// memory table runs in a child too.
template <class Job>
rusage in_child(Job job, int* status) {
  const pid_t pid = fork();
  if (pid < 0) throw Error("fork failed");
  if (pid == 0) _exit(job());
  rusage ru{};
  wait4(pid, status, 0, &ru);
  return ru;
}

/// The scenario at element size h and duration T with tracks from the truth.
Scenario with_observations(double h, double T, const std::string& dir, bool fork_truth) {
  Scenario truth = bench::remeshed(
      load_scenario(std::string(KELVIN_SOURCE_DIR) + "/yaml/examples/foam-cylinder.yaml"), h);
  truth.time.end = T;
  truth.time.output_rate = 180;
  SimulationOptions o;
  o.outdir = dir;
  const auto simulate = [&] {
    const SimulationResult r = run_simulation(truth, o);
    if (!r.completed) fmt::print(stderr, "truth simulation failed: {}\n", r.error);
    return r.completed ? 0 : 1;
  };
  bool ok = false;
  if (fork_truth) {
    int status = 0;
    in_child(simulate, &status);
    ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
  } else {
    ok = simulate() == 0;
  }
  if (!ok) throw Error("truth simulation failed");
  Scenario s = bench::observing(truth, dir);
  s.material.elastic[0].params["mu"] *= 1.3;
  s.material.elastic[0].params["lambda"] *= 0.7;
  s.material.viscous[0].params["nu"] *= 1.3;
  return s;
}

struct Timing {
  double seconds;
  long steps, backward_steps;
  int segments;
};

Timing time_evaluation(FitProblem& problem, GradientMethod method, int repeat,
                       long checkpoint_steps) {
  GradientOptions o;
  o.method = method;
  o.checkpoint_steps = checkpoint_steps;
  std::vector<double> t;
  Evaluation e;
  for (int k = 0; k < repeat; ++k) {
    e = problem.evaluate(problem.map().initial(), o);
    if (!e.ok) throw Error(e.error);
    t.push_back(e.seconds);
  }
  return {median(t), e.experiments[0].forward_stats.steps, e.experiments[0].backward_steps,
          e.experiments[0].segments};
}

/// Peak resident memory and wall time of one evaluation, run in a child process.
/// `evaluations` > 1 times the last one (the first of an experiment with automatic
/// segments also plans them, see EvaluationPlan::plan_segments).
struct Footprint {
  double mib = 0, seconds = 0;
  long steps = -1;
  int segments = 0;
};

Footprint footprint(const Scenario& s, const std::vector<FitParameterSpec>& specs,
                    GradientOptions o, int evaluations = 1) {
  int pipefd[2];
  if (pipe(pipefd) != 0) throw Error("pipe failed");
  int status = 0;
  const rusage ru = in_child(
      [&] {
        close(pipefd[0]);
        FitProblem problem(s, specs);
        Evaluation e;
        for (int k = 0; k < evaluations; ++k) e = problem.evaluate(problem.map().initial(), o);
        Footprint f;
        f.seconds = e.seconds;
        f.steps = e.ok ? e.experiments[0].forward_stats.steps : -1;
        f.segments = e.ok ? e.experiments[0].segments : 0;
        if (write(pipefd[1], &f, sizeof f) != sizeof f) return 2;
        return e.ok ? 0 : 1;
      },
      &status);
  close(pipefd[1]);
  Footprint f;
  if (read(pipefd[0], &f, sizeof f) != sizeof f) f = Footprint{};
  close(pipefd[0]);
  f.mib = ru.ru_maxrss / 1024.0;
  return f;
}

}  // namespace

int main(int argc, char** argv) {
  double h = 0.01, duration = 0.1, memory_base = 0.05, segment = 0.05;
  int repeat = 3, regions = 100, fsa_max = 100;
  long checkpoint_steps = 0;
  bool cost = true, memory = true;
  std::vector<double> factors = {1, 10, 100};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&] { return std::stod(argv[++i]); };
    if (a == "--h")
      h = next();
    else if (a == "--duration")
      duration = next();
    else if (a == "--repeat")
      repeat = static_cast<int>(next());
    else if (a == "--regions")
      regions = static_cast<int>(next());
    else if (a == "--memory-base")
      memory_base = next();
    else if (a == "--segment")
      segment = next();
    else if (a == "--checkpoint-steps")
      checkpoint_steps = static_cast<long>(next());
    else if (a == "--fsa-max")
      fsa_max = static_cast<int>(next());
    else if (a == "--memory-factors") {
      factors.clear();
      std::stringstream list(argv[++i]);
      for (std::string f; std::getline(list, f, ',');) factors.push_back(std::stod(f));
      if (factors.empty()) {
        fmt::print(stderr, "--memory-factors needs at least one factor\n");
        return 1;
      }
    } else if (a == "--skip-cost")
      cost = false;
    else if (a == "--skip-memory")
      memory = false;
    else {
      fmt::print(stderr, "unknown option {}\n", a);
      return 1;
    }
  }
  const std::string dir =
      (std::filesystem::temp_directory_path() / "kelvin-bench-gradient").string();
  std::filesystem::create_directories(dir);
  using Scope = FitParameterSpec::Scope;

  // First: no process may fork once this one has run CHOLMOD (see in_child).
  if (memory) {
    const double longest = *std::max_element(factors.begin(), factors.end());
    const Scenario s = with_observations(h, longest * memory_base, dir + "/memory", true);
    fmt::print(
        "\npeak resident memory (MiB), h = {} mm, 4 global parameters; automatic segments "
        "of ≤ {} steps; given segments of {} s\n",
        1e3 * h, default_checkpoint_steps(6 * s.mesh.num_nodes()) / 2, segment);
    fmt::print(
        "| duration (s) | steps | Φ alone | adjoint, automatic (segments) | adjoint, given "
        "segments | automatic / Φ | given / Φ | time: automatic / Φ | given / Φ |\n"
        "|---|---|---|---|---|---|---|---|---|\n");
    for (double factor : factors) {
      Scenario sc = s;
      sc.time.end = memory_base * factor;
      GradientOptions none, automatic, given;
      none.method = GradientMethod::kNone;
      none.segment = sc.time.end;  // one run from t₀, nothing to plan
      given.segment = segment;
      const Footprint f0 = footprint(sc, {}, none);
      const Footprint f1 = footprint(sc, {}, automatic, 2);
      const Footprint f2 = footprint(sc, {}, given);
      fmt::print(
          "| {:g} | {} | {:.1f} | {:.1f} ({}) | {:.1f} | {:.2f} | {:.2f} | {:.2f} | {:.2f} |\n",
          sc.time.end, f0.steps, f0.mib, f1.mib, f1.segments, f2.mib, f1.mib / f0.mib,
          f2.mib / f0.mib, f1.seconds / f0.seconds, f2.seconds / f0.seconds);
      std::fflush(stdout);
    }
  }
  if (cost) {
    const Scenario s = with_observations(h, duration, dir + "/cost", false);
    fmt::print("foam cylinder, h = {} mm: {} tets, {} dofs, {} s simulated, medians of {}\n",
               1e3 * h, s.mesh.num_tets(), 3 * s.mesh.num_nodes(), duration, repeat);
    auto slabs = positive_fit_parameter("elastic.mu", Scope::Boxes);
    for (int k = 0; k + 1 < regions; ++k) {
      const double z0 = 0.2 * k / regions, z1 = 0.2 * (k + 1) / regions;
      slabs.boxes.push_back({Eigen::Vector3d(-1, -1, z0), Eigen::Vector3d(1, 1, z1)});
    }
    struct Case {
      std::string name;
      std::vector<FitParameterSpec> specs;
      bool forward;
    };
    const std::vector<Case> cases = {
        {"4 global", {}, fsa_max >= 4},
        {"regions", {slabs}, regions <= fsa_max},
        {"per element", {positive_fit_parameter("elastic.mu", Scope::PerElement)}, false},
    };
    fmt::print(
        "| map | parameters | Φ alone (s) | Φ + adjoint (s) | ratio | backward/forward steps "
        "| segments | Φ + forward sens. (s) | ratio |\n|---|---|---|---|---|---|---|---|---|\n");
    for (const auto& c : cases) {
      FitProblem problem(s, c.specs);
      // Untimed: the first evaluation also chooses the automatic segments.
      time_evaluation(problem, GradientMethod::kNone, 1, checkpoint_steps);
      const Timing f = time_evaluation(problem, GradientMethod::kNone, repeat, checkpoint_steps);
      const Timing a = time_evaluation(problem, GradientMethod::kAdjoint, repeat, checkpoint_steps);
      std::string fwd = "- | -";
      if (c.forward) {
        const Timing t = time_evaluation(problem, GradientMethod::kForward, 1, checkpoint_steps);
        fwd = fmt::format("{:.3g} | {:.2f}", t.seconds, t.seconds / f.seconds);
      }
      fmt::print("| {} | {} | {:.3g} | {:.3g} | {:.2f} | {}/{} | {} | {} |\n", c.name,
                 problem.map().size(), f.seconds, a.seconds, a.seconds / f.seconds,
                 a.backward_steps, f.steps, a.segments, fwd);
      std::fflush(stdout);
    }
  }

  return 0;
}
