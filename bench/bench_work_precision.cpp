// Work-precision of kelvin's time integration against the Real2Sim paper's method
// on the same mesh, motion, material and objective: marker RMS error against a tight
// reference run (at the capture frames) versus wall time and steps, for
//   - kelvin's defaults (the scenario as shipped: no solver tuning),
//   - kelvin with its automatic BDF order over a range of rtol,
//   - IDAS at fixed maximum orders 1–5 over a range of rtol,
//   - the paper's fixed-step BDF2 with full Newton (bench/bdf2_baseline.hpp) at
//     1/180 s and finer, halving until it is within the finest target.
// Then, at each target accuracy (0.5 and 0.05 mm), the cheapest setting of each
// method, and kelvin's wall-time ratio to the baseline, forward alone and forward +
// gradient (kelvin: Φ + checkpointed adjoint; baseline: store-all discrete adjoint).
// Cases: V01 of yaml/examples/diagnosis (train motion, 1512 tets, lightly damped)
// and the bench bar of bench_fit (120 tets, strongly damped).
//
//   build/bin/bench_work_precision [--case v01|bar|all] [--quick] [--check-reference]
//                                  [--threads 1]
// --quick: fewer rtol values and fixed orders 2, 3 and 5 only.
// --threads: element-loop threads for every method (default 1: one core, so that
// the figures do not depend on what else runs; bench_assembly measures threads).
// A run that needs more than 200 000 steps is stopped and shown as failed.
// --check-reference: also simulate the reference at 10× tighter tolerances and print
// how far the two are apart (the reference's own error).
#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "adjoint/fit_problem.hpp"
#include "adjoint/marker_trajectory.hpp"
#include "base/error.hpp"
#include "bench/bdf2_baseline.hpp"
#include "bench/bench_bar.hpp"
#include "engine/threads.hpp"
#include "yaml/scenario.hpp"
#include "yaml/scenario_simulation.hpp"

namespace fs = std::filesystem;
using namespace kelvin;

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

constexpr double kTargets[] = {0.5e-3, 0.05e-3};  // m
constexpr long kMaxSteps = 200000;                // per run of a sweep

struct Case {
  std::string name;
  Scenario scenario;  // as shipped: kelvin's defaults
  std::vector<double> frames;
};

/// One run of one method at one setting.
struct Run {
  std::string method, setting;
  bool ok = false;
  std::string error;
  long steps = 0, probe_steps = 0;
  int order = 0;  // the cap used (auto: the one chosen)
  double wall = 0, error_m = NAN;
  SolverSpec solver;     // IDAS runs
  double bdf2_step = 0;  // baseline runs
};

/// Marker RMS distance between two sampled runs (all markers, all frames).
double rms_distance(const std::vector<Eigen::Matrix3Xd>& a,
                    const std::vector<Eigen::Matrix3Xd>& b) {
  double sum = 0;
  long count = 0;
  for (size_t k = 0; k < std::min(a.size(), b.size()); ++k) {
    sum += (a[k] - b[k]).colwise().squaredNorm().sum();
    count += a[k].cols();
  }
  return count ? std::sqrt(sum / count) : NAN;
}

Scenario with_solver(const Scenario& base, const SolverSpec& solver) {
  Scenario s = base;
  s.solver = solver;
  return s;
}

/// A fit problem of the case at one solver setting, its one-time work done: the
/// order probe (solver.max_order auto) and the segment plan happen at the first
/// evaluation of a fit, so they are done before anything is timed.
struct KelvinSetup {
  Scenario scenario;
  std::unique_ptr<FitProblem> problem;
  MarkerTrajectory tracks;  // sampled at the case's frames by the first run
  KelvinSetup(const Case& c, const SolverSpec& solver) : scenario(with_solver(c.scenario, solver)) {
    problem = std::make_unique<FitProblem>(scenario, scenario.fit.parameters);
    tracks = simulate_markers(*problem, 0, problem->map().initial(), c.frames, false);
  }
  Eigen::VectorXd p() const { return problem->map().initial(); }
};

/// kelvin's forward run: Φ at the case's start parameters, timed after the setup's
/// first run; its error from that run's samples against `ref` (none: the reference
/// itself, not timed).
Run kelvin_forward(const Case& c, const SolverSpec& solver,
                   const std::vector<Eigen::Matrix3Xd>* ref,
                   std::vector<Eigen::Matrix3Xd>* tracks = nullptr) {
  Run r;
  r.solver = solver;
  KelvinSetup setup(c, solver);
  r.ok = setup.tracks.ok;
  r.error = setup.tracks.error;
  const OrderChoice& choice = setup.problem->plan(0).order_choice();
  r.order = solver.max_order > 0 ? solver.max_order : choice.max_order;
  for (long steps : choice.steps) r.probe_steps += std::abs(steps);
  r.steps = setup.tracks.stats.steps;
  if (!r.ok || !ref) {  // the reference itself is not timed
    if (tracks) *tracks = std::move(setup.tracks.positions);
    return r;
  }
  GradientOptions phi_only;
  phi_only.method = GradientMethod::kNone;
  const auto start = Clock::now();
  const Evaluation e = setup.problem->evaluate(setup.p(), phi_only);
  r.wall = since(start);
  r.steps = e.experiments.at(0).forward_stats.steps;
  if (ref) r.error_m = rms_distance(setup.tracks.positions, *ref);
  if (tracks) *tracks = std::move(setup.tracks.positions);
  return r;
}

/// The baseline's ExperimentRun for the case at its start parameters.
struct BaselineSetup {
  Scenario scenario;
  std::unique_ptr<FitProblem> problem;
  explicit BaselineSetup(const Case& c) : scenario(c.scenario) {
    scenario.solver.max_order = 5;  // no order probe: the baseline integrates itself
    problem = std::make_unique<FitProblem>(scenario, scenario.fit.parameters);
  }
};

Run baseline(const Case& c, double h, const std::vector<Eigen::Matrix3Xd>& ref, bool adjoint,
             bench::Bdf2Result* result = nullptr) {
  Run r;
  r.method = "BDF2 fixed step (Real2Sim)";
  r.setting = fmt::format("h = 1/{:.0f} s", 1 / h);
  r.bdf2_step = h;
  r.order = 2;
  BaselineSetup setup(c);
  const auto start = Clock::now();
  const Eigen::VectorXd p = setup.problem->map().initial();
  setup.problem->map().apply(p, setup.problem->experiment(0).model());
  GradientOptions opt;
  ExperimentRun run(setup.problem->experiment(0), setup.problem->plan(0), setup.problem->map(), p,
                    opt);
  bench::Bdf2Result b = bench::bdf2_run(run, h, c.frames, adjoint);
  r.wall = since(start);
  r.ok = b.ok;
  r.error = b.error;
  r.steps = b.steps;
  if (b.ok) r.error_m = rms_distance(b.markers, ref);
  if (result) *result = std::move(b);
  return r;
}

/// Φ + adjoint gradient with kelvin at `solver`, timed after the setup's first run:
/// wall time, the gradient and the backward steps.
struct Gradient {
  double wall = 0;
  Eigen::VectorXd g;
  long forward_steps = 0, backward_steps = 0;
};
Gradient kelvin_gradient(const Case& c, const SolverSpec& solver) {
  KelvinSetup setup(c, solver);
  GradientOptions opt;
  opt.method = GradientMethod::kAdjoint;
  const auto start = Clock::now();
  const Evaluation e = setup.problem->evaluate(setup.p(), opt);
  Gradient out;
  out.wall = since(start);
  if (!e.ok) throw Error("kelvin's gradient failed: " + e.error);
  out.g = e.gradient;
  out.forward_steps = e.experiments.at(0).forward_stats.steps;
  out.backward_steps = e.experiments.at(0).backward_steps;
  return out;
}

std::string rtol_label(double rtol) {
  return fmt::format("rtol {:g}", rtol);
}

void print_run(const Run& r) {
  const std::string probe = r.probe_steps ? fmt::format(" (+{} probe)", r.probe_steps) : "";
  if (!r.ok) {
    fmt::print("| {} | {} | failed: {} | | | |\n", r.method, r.setting, r.error);
    return;
  }
  fmt::print("| {} | {} | {} | {}{} | {:.2f} | {:.4f} |\n", r.method, r.setting, r.order, r.steps,
             probe, r.wall, r.error_m * 1e3);
}

/// Cheapest run of `method` within `target`, if any.
const Run* cheapest(const std::vector<Run>& runs, const std::string& method, double target) {
  const Run* best = nullptr;
  for (const Run& r : runs)
    if (r.method == method && r.ok && r.error_m <= target && (!best || r.wall < best->wall))
      best = &r;
  return best;
}

double relative_difference(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return (a - b).norm() / std::max(b.norm(), 1e-300);
}

int run_case(Case c, bool quick, bool check_reference) {
  const Scenario& s = c.scenario;
  fmt::print("\n## {} ({} tets, {} s, {} frames; defaults: rtol {:g}, atol {:g}, max_order {})\n\n",
             c.name, s.mesh.num_tets(), s.time.end, c.frames.size(), s.solver.rtol, s.solver.atol,
             s.solver.max_order > 0 ? std::to_string(s.solver.max_order) : "auto");

  SolverSpec reference_solver = s.solver;
  reference_solver.rtol = 1e-8;
  reference_solver.atol = 1e-12;
  reference_solver.max_order = 5;
  std::vector<Eigen::Matrix3Xd> ref;
  const Run reference = kelvin_forward(c, reference_solver, nullptr, &ref);
  if (!reference.ok) throw Error("the reference run failed: " + reference.error);
  fmt::print("reference: IDAS order ≤ 5, rtol 1e-8, atol 1e-12: {} steps\n", reference.steps);
  if (check_reference) {
    SolverSpec tighter = reference_solver;
    tighter.rtol = 1e-9;
    tighter.atol = 1e-13;
    const Run check = kelvin_forward(c, tighter, &ref);
    fmt::print("reference check: rtol 1e-9 differs from it by {:.5f} mm RMS ({} steps)\n",
               check.error_m * 1e3, check.steps);
  }

  std::vector<Run> runs;
  {
    Run d = kelvin_forward(c, s.solver, &ref);
    d.method = "kelvin defaults";
    d.setting = rtol_label(s.solver.rtol);
    runs.push_back(d);
  }
  const std::vector<double> rtols =
      quick ? std::vector<double>{1e-2, 1e-3, 1e-4, 1e-5}
            : std::vector<double>{1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5};
  for (double rtol : rtols) {
    SolverSpec solver = s.solver;
    solver.rtol = rtol;
    solver.max_order = 0;
    solver.max_steps = kMaxSteps;
    Run r = kelvin_forward(c, solver, &ref);
    r.method = "kelvin auto order";
    r.setting = rtol_label(rtol);
    runs.push_back(r);
  }
  const std::vector<int> orders =
      quick ? std::vector<int>{2, 3, 5} : std::vector<int>{1, 2, 3, 4, 5};
  const std::vector<double> fixed_rtols = {1e-2, 1e-3, 1e-4, 1e-5};
  for (int order : orders)
    for (double rtol : fixed_rtols) {
      SolverSpec solver = s.solver;
      solver.rtol = rtol;
      solver.max_order = order;
      solver.max_steps = kMaxSteps;
      Run r = kelvin_forward(c, solver, &ref);
      r.method = fmt::format("IDAS order ≤ {}", order);
      r.setting = rtol_label(rtol);
      runs.push_back(r);
    }
  // The paper's step and finer ones, until the finest target is met.
  for (double h = 1.0 / 180; h > 1.0 / 50000; h /= 2) {
    runs.push_back(baseline(c, h, ref, false));
    if (runs.back().ok && runs.back().error_m <= kTargets[1]) break;
  }

  fmt::print(
      "\n| method | setting | order | steps | wall (s) | error (mm) "
      "|\n|---|---|---|---|---|---|\n");
  for (const Run& r : runs) print_run(r);

  const std::string kelvin_auto = "kelvin auto order", paper = "BDF2 fixed step (Real2Sim)";
  fmt::print(
      "\n| target (mm) | method | setting | forward (s) | ratio to baseline | forward + "
      "gradient (s) | ratio to baseline | gradient / forward "
      "|\n|---|---|---|---|---|---|---|---|\n");
  std::optional<Eigen::VectorXd> reference_gradient;
  for (double target : kTargets) {
    const Run* base = cheapest(runs, paper, target);
    double base_grad = NAN;
    Eigen::VectorXd base_g;
    if (base) {
      bench::Bdf2Result b;
      const Run with_adjoint = baseline(c, base->bdf2_step, ref, true, &b);
      if (with_adjoint.ok) {
        base_grad = with_adjoint.wall;
        base_g = b.gradient;
        fmt::print("| {:g} | {} | {} | {:.2f} | 1 | {:.2f} | 1 | {:.2f} (stored {:.0f} MiB) |\n",
                   target * 1e3, paper, base->setting, base->wall, base_grad,
                   base_grad / base->wall, b.stored_mib);
      }
    } else {
      fmt::print("| {:g} | {} | not reached | | | | | |\n", target * 1e3, paper);
    }
    for (const std::string& method :
         {std::string("kelvin defaults"), kelvin_auto, std::string("IDAS order ≤ 2"),
          std::string("IDAS order ≤ 5")}) {
      const Run* r = cheapest(runs, method, target);
      if (!r) {
        fmt::print("| {:g} | {} | not reached | | | | | |\n", target * 1e3, method);
        continue;
      }
      const Gradient grad = kelvin_gradient(c, r->solver);
      if (!reference_gradient) {
        SolverSpec tight = s.solver;
        tight.rtol = 1e-7;
        tight.atol = 1e-11;
        reference_gradient = kelvin_gradient(c, tight).g;
      }
      fmt::print(
          "| {:g} | {} | {} | {:.2f} | {:.1f}× | {:.2f} | {:.1f}× | {:.2f} ({} forward, {} "
          "backward "
          "steps; gradient off by {:.1e}) |\n",
          target * 1e3, method, r->setting, r->wall, base ? base->wall / r->wall : NAN, grad.wall,
          base_grad / grad.wall, grad.wall / r->wall, grad.forward_steps, grad.backward_steps,
          relative_difference(grad.g, *reference_gradient));
    }
    if (base && base_g.size() && reference_gradient)
      fmt::print("|  |  | baseline gradient off by {:.1e} |  |  |  |  |  |\n",
                 relative_difference(base_g, *reference_gradient));
  }
  std::fflush(stdout);
  return 0;
}

std::vector<double> frame_times(double end, double rate) {
  std::vector<double> t;
  const long count = std::lround(std::floor(end * rate + 1e-9));
  for (long k = 0; k <= count; ++k) t.push_back(std::min(end, k / rate));
  return t;
}

Case v01_case() {
  Case c;
  c.name = "V01 train (yaml/examples/diagnosis/V01-none/train.yaml, λ 2×, μ 0.7×, ν 2× off)";
  c.scenario = load_scenario(KELVIN_SOURCE_DIR "/yaml/examples/diagnosis/V01-none/train.yaml");
  // Away from the fitted point, where the gradient is mostly the capture noise's.
  c.scenario.material.elastic[0].params["lambda"] *= 2;
  c.scenario.material.elastic[0].params["mu"] *= 0.7;
  c.scenario.material.viscous[0].params["nu"] *= 2;
  c.frames = frame_times(c.scenario.time.end, c.scenario.time.output_rate);
  return c;
}

/// The bench bar with tracks of its truth at rtol 1e-9, fitted from 2×/½× off.
Case bar_case(const fs::path& dir) {
  fs::create_directories(dir);
  const double duration = 2, rate = 180;
  std::ofstream(dir / "truth.yaml")
      << bench::bar_scenario(bench::kBarTruthMaterial, duration, rate,
                             "{ rtol: 1.0e-9, atol: 1.0e-13, max_order: 5 }", "");
  SimulationOptions so;
  so.outdir = (dir / "truth").string();
  const SimulationResult truth = run_simulation(load_scenario((dir / "truth.yaml").string()), so);
  if (!truth.completed) throw Error("bar truth failed: " + truth.error);
  const std::string start = R"(  density: 1100
  elastic: { model: neo-hookean, lambda: 1.2e6, mu: 1.5e5 }
  viscous: { model: power-law, nu: 40, h: 1.6 })";
  std::ofstream(dir / "bar.yaml") << bench::bar_scenario(
      start, duration, rate, "{ }",
      "  observed: " + (dir / "truth" / "markers.csv").string() +
          "\nfit: { parameters: [elastic.lambda, elastic.mu, viscous.nu, viscous.h] }\n");
  Case c;
  c.name = "bench bar (bench_fit's, at its 2×-off start)";
  c.scenario = load_scenario((dir / "bar.yaml").string());
  c.frames = frame_times(duration, rate);
  return c;
}

}  // namespace

int main(int argc, char** argv) {
  std::string which = "all";
  bool quick = false, check_reference = false;
  int threads = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--case" && i + 1 < argc)
      which = argv[++i];
    else if (a == "--quick")
      quick = true;
    else if (a == "--check-reference")
      check_reference = true;
    else if (a == "--threads" && i + 1 < argc)
      threads = std::atoi(argv[++i]);
    else {
      fmt::print(stderr, "unknown option {}\n", a);
      return 1;
    }
  }
  try {
    set_threads(threads);
    fmt::print(
        "# Work-precision: marker RMS error against a reference run, wall time and steps ({} "
        "thread{})\n",
        threads, threads == 1 ? "" : "s");
    if (which == "v01" || which == "all") run_case(v01_case(), quick, check_reference);
    if (which == "bar" || which == "all")
      run_case(bar_case(fs::temp_directory_path() / "kelvin-bench-work-precision"), quick,
               check_reference);
  } catch (const Error& e) {
    fmt::print(stderr, "error: {}\n", e.what());
    return 2;
  }
  return 0;
}
