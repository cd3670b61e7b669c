#pragma once
// Subcommands of the `kelvin` executable; each registers its options on the app.
#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <cmath>
#include <cstdlib>

#include "yaml/scenario.hpp"

namespace kelvin {

/// Set by SIGINT/SIGTERM; long-running commands poll it and save what they have.
extern std::atomic<bool> g_interrupted;

/// Exit codes shared by all commands.
enum ExitCode { kExitOk = 0, kExitInputError = 1, kExitRunFailed = 2, kExitInterrupted = 130 };

/// Option checks with short messages (CLI11's own print the bound of a double in
/// full): a finite number above (or, with zero_ok, at least) 0.
inline CLI::Validator positive_number(bool zero_ok = false) {
  return CLI::Validator(
      [zero_ok](std::string& value) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(value.c_str(), &end);
        if (end == value.c_str() || *end != '\0' || !std::isfinite(v) || v < 0 ||
            (v == 0 && !zero_ok))
          return fmt::format("must be a {} finite number (got '{}')",
                             zero_ok ? "non-negative" : "positive", value);
        return "";
      },
      zero_ok ? "NONNEGATIVE" : "POSITIVE");
}

/// Creates the output directory `dir` (option `-o`) and checks that files can be
/// written in it; "" when they can, else why not.
std::string prepare_output_dir(const std::string& dir);

/// Prints what the scenario loader adjusted (Scenario::notes), once per run.
inline void print_notes(const Scenario& scenario) {
  for (const auto& note : scenario.notes) fmt::print("note: {}\n", note);
}

void register_simulate(CLI::App& app, int& exit_code);
void register_check_material(CLI::App& app, int& exit_code);
void register_gradcheck(CLI::App& app, int& exit_code);
void register_fit(CLI::App& app, int& exit_code);
void register_capture(CLI::App& app, int& exit_code);
void register_diagnose(CLI::App& app, int& exit_code);
void register_probe(CLI::App& app, int& exit_code);

}  // namespace kelvin
