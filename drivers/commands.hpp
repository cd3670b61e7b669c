#pragma once
// Subcommands of the `kelvin` executable; each registers its options on the app.
#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <atomic>

#include "yaml/scenario.hpp"

namespace kelvin {

/// Set by SIGINT/SIGTERM; long-running commands poll it and save what they have.
extern std::atomic<bool> g_interrupted;

/// Exit codes shared by all commands.
enum ExitCode { kExitOk = 0, kExitInputError = 1, kExitRunFailed = 2, kExitInterrupted = 130 };

/// Prints what the scenario loader adjusted (Scenario::notes), once per run.
inline void print_notes(const Scenario& scenario) {
  for (const auto& note : scenario.notes) fmt::print("note: {}\n", note);
}

void register_simulate(CLI::App& app, int& exit_code);
void register_check_material(CLI::App& app, int& exit_code);
void register_gradcheck(CLI::App& app, int& exit_code);
void register_fit(CLI::App& app, int& exit_code);
void register_capture(CLI::App& app, int& exit_code);

}  // namespace kelvin
