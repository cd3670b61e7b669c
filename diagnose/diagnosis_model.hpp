#pragma once
/// \file
/// The models a diagnosis runs: a scenario file extended by candidates, loaded with
/// its fit problem, and the screening's Gauss–Newton system of such a model
/// computed one candidate at a time.
#include <Eigen/Core>
#include <atomic>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "adjoint/fit_problem.hpp"
#include "adjoint/uncertainty.hpp"
#include "base/spread_tasks.hpp"
#include "diagnose/extended_scenario.hpp"

namespace kelvin {

/// One loaded scenario file and its fit problem (the scenario must outlive it).
struct Model {
  std::unique_ptr<Scenario> scenario;
  std::unique_ptr<FitProblem> problem;
  ExtendedScenario extended;
};

/// Writes `path` from `source` extended by `with` (see write_extended_scenario) and
/// loads it, its experiments spread over `comm`. Static measurements are refused: the
/// stages read captured motion.
Model load_model(const std::string& source, const Scenario& nominal,
                 const std::vector<const Candidate*>& with, bool screening, const std::string& path,
                 int refit_form = -1, Communicator& comm = world());

/// The entries of m's map that fit.parameters specs `specs` make, in order.
std::vector<int> entries_of(const Model& m, const std::vector<int>& specs);

/// The Gauss–Newton system (r, J) at p of `m`, the screening model that load_model
/// made from `source` and `with` (screened form, with[refit_form] an accepted effect
/// at its refit), computed without integrating every candidate's terms and
/// sensitivities together: a nested candidate at its nominal value leaves the tracks
/// where the model without it puts them, so its columns of J are those of the base
/// model (the nominal one and with[refit_form]) extended by it alone. One run of the
/// base model, with the candidates whose columns need no sensitivities of their own
/// (marker offsets, the clock, the registration), gives r and the base's columns; each other candidate's
/// run integrates its own sensitivities only: in a joint run every candidate's terms
/// would slow every step of every sensitivity. The per-candidate models are written
/// to `dir`/`stem`-<id>.yaml. `m` must have been made from `with` and `refit_form`.
/// The runs are spread over the ranks of `comm` (each on its rank alone); every rank
/// gets the whole system. `beside`, when given, is spread with them: work of another
/// stage that needs none of them. With `costs` holding every run's seconds from an
/// earlier screening and no `beside` (whose cost is not known on that scale: V09's
/// runs took 4–5× longer at the refit than at the nominal fit), the runs are balanced
/// by them, else dealt round robin; each run's seconds are put there.
struct BesideTask {
  SpreadTask run;
  ProgressLine progress;  // of its lines
  std::string result;     // packed, on every rank
};
/// Seconds of each screening run: "base", or a candidate's id (-where).
using ScreeningCosts = std::map<std::string, double>;
GaussNewtonSystem screening_system(const Model& m, const std::string& source,
                                   const Scenario& nominal,
                                   const std::vector<const Candidate*>& with, int refit_form,
                                   const Eigen::VectorXd& p, const std::filesystem::path& dir,
                                   const std::string& stem, const std::atomic<bool>* interrupt,
                                   Communicator& comm = world(), BesideTask* beside = nullptr,
                                   ScreeningCosts* costs = nullptr);

}  // namespace kelvin
