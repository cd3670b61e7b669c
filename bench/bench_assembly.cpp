// Element loops on 1 … N threads (OpenMP): wall time per call of the residual's
// force assembly, the Newton matrix's K and D, and the adjoint's per-state work
// (tangents with dP/dq, then Kᵀλ and Dᵀλ), on the bundled foam cylinder re-meshed
// at --h (default 4 mm, 8.1k tets), at a deformed, moving state. Prints the
// speed-up over one thread; the results are identical by construction (test_threads).
//
//   build/bin/bench_assembly [--h 0.004] [--repeat 200] [--threads-max N]
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "bench/foam_cylinder.hpp"
#include "engine/dae_system.hpp"
#include "engine/threads.hpp"
#include "yaml/scenario.hpp"
#include "yaml/scenario_simulation.hpp"

using namespace kelvin;

namespace {

template <class F>
double per_call(int repeat, F f) {
  f();  // warm-up: sizes the workspaces
  const auto start = std::chrono::steady_clock::now();
  for (int r = 0; r < repeat; ++r) f();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() / repeat;
}

}  // namespace

int main(int argc, char** argv) {
  double h = 0.004;
  int repeat = 200, threads_max = thread_count();
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--h") && i + 1 < argc)
      h = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--repeat") && i + 1 < argc)
      repeat = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--threads-max") && i + 1 < argc)
      threads_max = std::atoi(argv[++i]);
    else {
      fmt::print(stderr, "unknown option {}\n", argv[i]);
      return 1;
    }
  }
  const Scenario base = load_scenario(KELVIN_SOURCE_DIR "/yaml/examples/foam-cylinder.yaml");
  const Scenario s = bench::remeshed(base, h);
  auto model = build_model(s);
  const int n = model->num_dofs();
  Eigen::VectorXd x0, v0;
  initial_state(s, *model, x0, v0);
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::VectorXd y(2 * n), yp = Eigen::VectorXd::Zero(2 * n), r(2 * n), lambda(n), kt(n), dt(n);
  for (int i = 0; i < n; ++i) {
    y[i] = x0[i] + 1e-4 * u(rng);
    y[n + i] = 0.05 * u(rng);
    lambda[i] = u(rng);
  }
  fmt::print("foam cylinder, h = {} mm: {} tets, {} dofs; {} calls each\n\n", 1e3 * h,
             s.mesh.num_tets(), n, repeat);
  fmt::print(
      "| threads | residual (ms) | K and D (ms) | adjoint state (ms) | speed-up: residual | K, D "
      "| adjoint |\n|---|---|---|---|---|---|---|\n");
  double base_r = 0, base_k = 0, base_a = 0;
  for (int threads = 1; threads <= threads_max; ++threads) {
    set_threads(threads);
    DaeSystem dae(*model);
    ElementSlots slots;
    const double tr = per_call(repeat, [&] { dae.residual(0.01, y.data(), yp.data(), r.data()); });
    const double tk = per_call(repeat / 4 + 1, [&] { dae.stiffness_and_damping(0.01, y.data()); });
    const double ta = per_call(repeat / 4 + 1, [&] {
      dae.element_tangents(0.01, y.data(), true);
      model->transpose_multiply(dae.tangents(), lambda.data(), kt.data(), dt.data(), slots);
    });
    if (threads == 1) base_r = tr, base_k = tk, base_a = ta;
    fmt::print("| {} | {:.3f} | {:.3f} | {:.3f} | {:.2f}× | {:.2f}× | {:.2f}× |\n", threads,
               1e3 * tr, 1e3 * tk, 1e3 * ta, base_r / tr, base_k / tk, base_a / ta);
  }
  return 0;
}
