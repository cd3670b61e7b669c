#pragma once
// Helpers shared by the tests: scratch directories, text files, running the
// kelvin binary, and simulating "captured" marker tracks with known parameters.
#include <fmt/format.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include "engine/csv.hpp"
#include "yaml/scenario.hpp"
#include "yaml/scenario_simulation.hpp"

namespace kelvin::test {

namespace fs = std::filesystem;

/// A fresh, empty directory under the system temp dir.
inline fs::path scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("kelvin-test-" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

inline void write_text(const fs::path& path, const std::string& text) {
  std::ofstream(path) << text;
}

inline std::string read_text(const fs::path& path) {
  std::ifstream in(path);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

struct CliRun {
  int exit_code = -1;
  std::string out;  // stdout and stderr
};

/// Runs a shell command and captures its output.
inline CliRun run_command(const std::string& command) {
  const std::string cmd = command + " 2>&1";
  CliRun r;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  while (size_t n = fread(buf, 1, sizeof buf, p)) r.out.append(buf, n);
  const int status = pclose(p);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
}

/// Runs `kelvin <args>` and captures its output.
inline CliRun run_kelvin(const std::string& args) {
  return run_command(std::string(KELVIN_BINARY) + " " + args);
}

/// The synthetic specimen of the gradient and fit tests: a 60 × 20 × 20 mm bar
/// (144 tets) clamped at x = 0 and shaken by two sinusoids (17 Hz along y, 13 Hz
/// along z, starting at rest), hanging under gravity from a static initial state.
/// `material` is the indented body of the material section; `tail` follows the
/// solver section (markers, fit, ...).
struct ShakenBar {
  std::string name = "bar";
  std::string material;
  double amplitude_y = 0.003, amplitude_z = 0.002;  // m
  double frequency_y = 17, frequency_z = 13;        // Hz
  double end = 0.1, output_rate = 200;              // s, Hz
  double rtol = 1e-9, atol = 1e-13;
  std::string clamp_keys;              // more keys of the clamp's entry, e.g. "compliance: 1e-7"
  std::string mesh_keys, solver_keys;  // more keys of those mappings, e.g. ", refine: 1"
  std::string tail;
};

/// Three markers on the shaken bar (free end, middle, between), as a `markers:` section.
inline const std::string kShakenBarMarkers = R"(
markers:
  rest:
    - { name: tip, at: [0.06, 0.01, 0.01] }
    - { name: mid, at: [0.03, 0.01, 0.02] }
    - { name: top, at: [0.045, 0.01, 0.02] })";

inline std::string shaken_bar_yaml(const ShakenBar& b) {
  return fmt::format(R"(
name: {}
mesh: {{ generate: box, lo: [0, 0, 0], hi: [0.06, 0.02, 0.02], element_size: 0.01{} }}
material:
{}
gravity: [0, 0, -9.81]
initial: static
clamps:
  - name: base
    select: {{ plane: {{ axis: x, at: 0 }} }}
    {}
    motion:
      sinusoids:
        translation:
          - {{ amplitude: {}, frequency: {}, phase: -1.5707963267948966, direction: [0, 1, 0] }}
          - {{ amplitude: {}, frequency: {}, phase: -1.5707963267948966, direction: [0, 0, 1] }}
time: {{ end: {}, output_rate: {} }}
solver: {{ rtol: {}, atol: {}{} }}
)",
                     b.name, b.mesh_keys, b.material, b.clamp_keys, b.amplitude_y, b.frequency_y,
                     b.amplitude_z, b.frequency_z, b.end, b.output_rate, b.rtol, b.atol,
                     b.solver_keys) +
         b.tail;
}

/// Simulates the scenario file `yaml` (written to dir/name.yaml) and returns the
/// path of its markers.csv: synthetic captured tracks with known parameters.
inline std::string simulate_tracks(const fs::path& dir, const std::string& name,
                                   const std::string& yaml) {
  write_text(dir / (name + ".yaml"), yaml);
  SimulationOptions o;
  o.outdir = (dir / name).string();
  const SimulationResult r = run_simulation(load_scenario((dir / (name + ".yaml")).string()), o);
  if (!r.completed) throw std::runtime_error("truth simulation failed: " + r.error);
  return (dir / name / "markers.csv").string();
}

/// Writes tracks in the wide layout read_marker_tracks reads; returns the path.
inline std::string write_marker_tracks(const MarkerTracks& t, const fs::path& out) {
  std::string csv = "t";
  for (const auto& m : t.names) csv += "," + m + "_x," + m + "_y," + m + "_z";
  csv += "\n";
  for (long k = 0; k < t.xyz.cols(); ++k) {
    csv += fmt::format("{:.12g}", t.times[k]);
    for (long r = 0; r < t.xyz.rows(); ++r) csv += fmt::format(",{:.12g}", t.xyz(r, k));
    csv += "\n";
  }
  write_text(out, csv);
  return out.string();
}

/// Adds N(0, σ²) to every coordinate of a track file.
inline std::string noisy_tracks(const std::string& file, const fs::path& out, double sigma,
                                unsigned seed) {
  MarkerTracks t = read_marker_tracks(file);
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0, sigma);
  for (long k = 0; k < t.xyz.cols(); ++k)
    for (long r = 0; r < t.xyz.rows(); ++r) t.xyz(r, k) += n(rng);
  return write_marker_tracks(t, out);
}

}  // namespace kelvin::test
