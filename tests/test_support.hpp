#pragma once
// Helpers shared by the tests: scratch directories, text files, running the
// kelvin binary, and simulating "captured" marker tracks with known parameters.
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "engine/simulation.hpp"
#include "yaml/scenario.hpp"

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

/// Runs `kelvin <args>` and captures its output.
inline CliRun run_kelvin(const std::string& args) {
  const std::string cmd = std::string(KELVIN_BINARY) + " " + args + " 2>&1";
  CliRun r;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  while (size_t n = fread(buf, 1, sizeof buf, p)) r.out.append(buf, n);
  const int status = pclose(p);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
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

}  // namespace kelvin::test
