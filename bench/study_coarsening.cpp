// The Real2Sim coarsening experiment (Hahn et al. 2019, Table 1 and Fig. 3):
// a fine simulation (≥ 30k tets) of a bar shaken by two sinusoids (17 and 13 Hz)
// is the truth; λ, μ and ν are fitted to its markers on three coarser meshes.
// Linear tetrahedra are too stiff on coarse meshes, so the fits should come out
// softer as the mesh coarsens, lower the misfit below that of the truth
// parameters on each coarse mesh, and carry over to a second motion in another
// plane better than the truth parameters do.
//
//   build/bin/study_coarsening [--fine 0.00125] [--coarse 0.01,0.005,0.0033333]
//                              [--duration 0.3] [--rate 500] [--outdir DIR]
//                              [--max-evaluations 60]
// Prints a Markdown table and writes it, with the scenarios and the fine tracks,
// to DIR (default: a temporary directory); the bundled copy is
// yaml/examples/coarsening/README.md.
#include <fmt/format.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "adjoint/fit_problem.hpp"
#include "base/error.hpp"
#include "fit/fit_loop.hpp"
#include "yaml/scenario.hpp"
#include "yaml/scenario_simulation.hpp"

namespace fs = std::filesystem;
using namespace kelvin;

namespace {

struct Options {
  double fine = 0.00125, duration = 0.25, rate = 500;
  std::vector<double> coarse = {0.01, 0.005, 0.01 / 3};
  int max_evaluations = 60;
  fs::path outdir = fs::temp_directory_path() / "kelvin-coarsening";
};

/// The two motions of the clamped end: the training motion in the y–z plane (the
/// paper's 17 and 13 Hz) and the held-out one in the x–z plane.
struct Motion {
  std::string name, plane, yaml;
};
const Motion kMotions[] = {
    {"A", "y–z",
     R"(          - { amplitude: 0.002, frequency: 17, phase: -1.5707963267948966, direction: [0, 1, 0] }
          - { amplitude: 0.0015, frequency: 13, phase: -1.5707963267948966, direction: [0, 0, 1] })"},
    {"B", "x–z",
     R"(          - { amplitude: 0.001, frequency: 13, phase: -1.5707963267948966, direction: [1, 0, 0] }
          - { amplitude: 0.002, frequency: 17, phase: -1.5707963267948966, direction: [0, 0, 1] })"},
};

/// 100 × 10 × 10 mm silicone-like bar clamped at x = 0, ten surface markers. The bar is
/// slender so that the ≥ 30k-tet truth stays affordable: KLU's fill grows with the
/// cross-section (a 60 × 20 × 20 mm bar at 31k tets needed seconds per refactorization).
std::string bar(double h, const Motion& m, const Options& o, const std::string& observed) {
  std::string yaml = fmt::format(R"(name: coarsening-{}-h{:.2f}mm
mesh: {{ generate: box, lo: [0, 0, 0], hi: [0.1, 0.01, 0.01], element_size: {:.9g} }}
material:
  density: 1100
  elastic: {{ model: neo-hookean, lambda: 6.0e5, mu: 3.0e5 }}
  viscous: {{ model: power-law, nu: 20, h: 0.8 }}
gravity: [0, 0, -9.81]
initial: static
clamps:
  - name: base
    select: {{ plane: {{ axis: x, at: 0 }} }}
    motion:
      sinusoids:
        translation:
{}
time: {{ end: {}, output_rate: {} }}
solver: {{ rtol: 1.0e-7, atol: 1.0e-11 }}
markers:
  rest:
)",
                                 m.name, 1e3 * h, h, m.yaml, o.duration, o.rate);
  for (double x : {0.025, 0.05, 0.075, 0.1})
    yaml += fmt::format(
        "    - {{ name: top{0:.0f}, at: [{1}, 0.005, 0.01] }}\n"
        "    - {{ name: side{0:.0f}, at: [{1}, 0.0, 0.005] }}\n",
        1e3 * x, x);
  yaml +=
      "    - { name: end_corner, at: [0.1, 0.01, 0.0] }\n"
      "    - { name: end_centre, at: [0.1, 0.005, 0.005] }\n";
  if (!observed.empty())
    yaml += "  observed: " + observed +
            "\nfit: { parameters: [elastic.lambda, elastic.mu, viscous.nu] }\n";
  return yaml;
}

fs::path write(const fs::path& p, const std::string& text) {
  std::ofstream(p) << text;
  return p;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double rms_at(FitProblem& problem, const Eigen::VectorXd& p) {
  GradientOptions none;
  none.method = GradientMethod::kNone;
  const Evaluation e = problem.evaluate(p, none);
  if (!e.ok) throw Error(e.error);
  return e.rms;
}

std::vector<double> parse_list(const std::string& s) {
  std::vector<double> v;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');) v.push_back(std::stod(item));
  return v;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) {
      fmt::print(stderr, "option {} needs a value\n", a);
      return 1;
    }
    const std::string v = argv[++i];
    if (a == "--fine")
      o.fine = std::stod(v);
    else if (a == "--coarse")
      o.coarse = parse_list(v);
    else if (a == "--duration")
      o.duration = std::stod(v);
    else if (a == "--rate")
      o.rate = std::stod(v);
    else if (a == "--max-evaluations")
      o.max_evaluations = std::stoi(v);
    else if (a == "--outdir")
      o.outdir = v;
    else {
      fmt::print(stderr, "unknown option {}\n", a);
      return 1;
    }
  }
  fs::create_directories(o.outdir);
  try {
    // The truth: both motions on the fine mesh.
    std::vector<std::string> tracks;
    int fine_tets = 0;
    for (const Motion& m : kMotions) {
      const fs::path yaml = write(o.outdir / ("truth-" + m.name + ".yaml"), bar(o.fine, m, o, ""));
      const Scenario s = load_scenario(yaml.string());
      fine_tets = s.mesh.num_tets();
      fmt::print("truth, motion {} ({} plane): {} tets ... ", m.name, m.plane, fine_tets);
      std::fflush(stdout);
      SimulationOptions so;
      so.outdir = (o.outdir / ("truth-" + m.name)).string();
      const auto t0 = std::chrono::steady_clock::now();
      const SimulationResult r = run_simulation(s, so);
      if (!r.completed) throw Error("truth simulation failed: " + r.error);
      fmt::print("{:.0f} s, {} steps\n", seconds_since(t0), r.stats.steps);
      tracks.push_back("truth-" + m.name + "/markers.csv");  // relative to the scenarios
    }

    std::string table = fmt::format(
        "| element size (mm) | tets | λ (kPa) | μ (kPa) | ν (Pa s) | RMS A, truth → fit (mm) "
        "| RMS B (held out), truth → fit (mm) | simulations | wall (s) |\n"
        "|---|---|---|---|---|---|---|---|---|\n"
        "| {:.2f} (truth) | {} | 600 | 300 | 20 | 0 | 0 | - | - |\n",
        1e3 * o.fine, fine_tets);
    fmt::print("\n{}", table);
    for (double h : o.coarse) {
      const Scenario a =
          load_scenario(write(o.outdir / fmt::format("fit-A-h{:.2f}mm.yaml", 1e3 * h),
                              bar(h, kMotions[0], o, tracks[0]))
                            .string());
      const Scenario b =
          load_scenario(write(o.outdir / fmt::format("check-B-h{:.2f}mm.yaml", 1e3 * h),
                              bar(h, kMotions[1], o, tracks[1]))
                            .string());
      FitProblem fit_a(a, a.fit.parameters), check_b(b, b.fit.parameters);
      const Eigen::VectorXd truth = fit_a.map().initial();  // the scenario holds the truth
      const double a0 = rms_at(fit_a, truth), b0 = rms_at(check_b, truth);
      FitOptions fo;
      fo.max_evaluations = o.max_evaluations;
      fo.ftol_rel = 1e-10;
      const auto t0 = std::chrono::steady_clock::now();
      const FitOutcome out = run_fit(fit_a, truth, fo);
      const double wall = seconds_since(t0);
      const double b1 = rms_at(check_b, out.p);
      const auto q = [&](int j) { return fit_a.map().value(out.p, j); };
      const std::string row = fmt::format(
          "| {:.2f} | {} | {:.1f} | {:.1f} | {:.2f} | {:.4f} → {:.4f} | {:.4f} → {:.4f} | {} | "
          "{:.0f} |\n",
          1e3 * h, a.mesh.num_tets(), 1e-3 * q(0), 1e-3 * q(1), q(2), 1e3 * a0, 1e3 * out.best.rms,
          1e3 * b0, 1e3 * b1, out.evaluations, wall);
      table += row;
      fmt::print("{}", row);
      std::fflush(stdout);
    }
    write(o.outdir / "table.md", table);
  } catch (const Error& e) {
    fmt::print(stderr, "error: {}\n", e.what());
    return 2;
  }
  return 0;
}
