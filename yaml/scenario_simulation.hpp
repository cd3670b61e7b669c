#pragma once
/// \file
/// A forward run of a scenario: model construction, initial state (rest or static
/// equilibrium), IDAS integration, marker CSV, VTU/PVD frames and a run summary.
/// Outputs already written survive a solver failure or an interrupt.
#include <atomic>
#include <memory>
#include <optional>
#include <string>

#include "engine/fem_model.hpp"
#include "engine/idas_integrator.hpp"
#include "engine/order_policy.hpp"
#include "engine/static_solver.hpp"
#include "yaml/scenario.hpp"

namespace kelvin {

/// The FEM model a scenario describes (the scenario must outlive it).
std::unique_ptr<FemModel> build_model(const Scenario& scenario);

/// The scenario's solver settings; max_order 0 (auto) is left for the caller to
/// resolve with choose_max_order.
IntegratorOptions integrator_options(const SolverSpec& solver);

/// Initial free-dof positions and velocities: rest, or static equilibrium at t = 0.
/// Throws kelvin::Error when the static solve fails.
void initial_state(const Scenario& scenario, const FemModel& model, Eigen::VectorXd& x0,
                   Eigen::VectorXd& v0, StaticResult* static_result = nullptr);

struct SimulationResult {
  bool completed = false;
  bool interrupted = false;
  double t_reached = 0;
  std::string error;
  IntegratorStats stats;
  StaticResult static_result;
  std::optional<OrderChoice> order;  // when solver.max_order is auto
  double wall_seconds = 0;
  int marker_frames = 0, vtu_frames = 0;
  std::string summary() const;  // one line for people
};

struct SimulationOptions {
  std::string outdir;                            // created if missing
  const std::atomic<bool>* interrupt = nullptr;  // set by a signal handler to stop early
  bool progress = false;                         // periodic progress lines on stderr
};

SimulationResult run_simulation(const Scenario& scenario, const SimulationOptions& options);

}  // namespace kelvin
