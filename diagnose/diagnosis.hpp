#pragma once
/// \file
/// `kelvin diagnose`: the sim-to-real gap of a nominal model, in stages.
///  1. Nominal fit on the training experiments; the noise level from the residual's
///     fast part (diagnose/noise).
///  2. Where: residual tables per marker, window, band and region (diagnose/where),
///     and the missing-force field of the nominal model (diagnose/missing_force).
///  3. Which: every candidate effect (diagnose/candidates) scored at the nominal fit
///     from one forward-sensitivity solve, ranked greedily (diagnose/ranking), the top
///     ones refitted with the nominal parameters free and checked on held-out motions.
///  4. How far: training and held-out RMS before and after, the effect's parameters
///     with standard errors.
///  5. When no named candidate is accepted but the nominal model leaves more than
///     noise: a learned stress correction (diagnose/learned_correction), judged like
///     a candidate and named `unnamed` when it passes.
/// An effect is named when its refit clears a likelihood-ratio test against the
/// estimated noise on the training data and, when held-out motions are given, lowers
/// their misfit by more than the noise can explain; otherwise the verdict is `none`.
#include <Eigen/Core>
#include <atomic>
#include <functional>
#include <string>
#include <vector>

#include "diagnose/candidates.hpp"
#include "diagnose/diagnose_settings.hpp"
#include "diagnose/learned_correction.hpp"
#include "diagnose/missing_force.hpp"
#include "diagnose/named_value.hpp"
#include "diagnose/noise.hpp"
#include "diagnose/ranking.hpp"
#include "diagnose/where.hpp"
#include "fit/stiffness_scan.hpp"

namespace kelvin {

/// Misfit of one model on one set of experiments at the capture frames.
struct MisfitFigures {
  bool ok = false;
  std::string error;
  double rms = 0;     // per coordinate (m)
  double sum_sq = 0;  // ‖r‖² (m²)
  int samples = 0;
  Eigen::VectorXd residual;             // for comparisons between models on the same samples
  std::vector<ResidualSample> entries;  // of residual: experiment, marker, axis, frame
};

struct HeldOutFigures {
  std::string path;
  std::vector<std::string> marker_names;  // of its objective (ResidualSample::marker)
  MisfitFigures before, after;
};

struct RefitResult {
  int candidate = -1;  // index into Diagnosis::candidates
  /// The accepted effect (index into Diagnosis::candidates) the candidate was added
  /// to, at its refit, and judged against; -1: added to the nominal model.
  int on_top_of = -1;
  bool ok = false;
  std::string error;
  int evaluations = 0;
  double seconds = 0;    // of the refit and its held-out checks
  MisfitFigures train;   // after (the nominal's is Diagnosis::nominal_train)
  double statistic = 0;  // (‖r₀‖² − ‖r‖²) / σ̂²: likelihood ratio, known noise
  double threshold = 0;  // χ²(dof) quantile at α / refits
  int dof = 0;
  double bic = 0;  // ‖r‖²/σ̂² + k ln N, k counting the nominal's too
  std::vector<HeldOutFigures> heldout;
  double heldout_drop = 0;  // Σ (‖h₀‖² − ‖h‖²) (m²)
  double heldout_threshold = 0;  // 2 z σ̂ ‖h − h₀‖ at α over the refits: what noise alone could give
  bool passes_training = false, passes_heldout = false;
  /// The refit ended above the nominal misfit (a local minimum, a budget spent far
  /// out): reported at the nominal point, which every nested candidate contains.
  bool at_nominal = false;
  std::string where;  // marker, or region of a field's largest change
  std::vector<NamedValue> parameters;
  /// The nominal parameters as refitted with the effect: what they had absorbed
  /// (a clock lag fitted as viscosity; a learned correction traded against μ); for a
  /// second effect, those of the model it was added to (the first effect's too).
  std::vector<NamedValue> nominal_parameters;
  /// What the standard errors rest on when not on the whole JᵀJ (entries held), or
  /// why there are none; "" when they are the plain Gauss–Newton ones.
  std::string errors_note;
  std::string fitted_yaml;          // the refitted scenario, runnable by `kelvin simulate`
  Eigen::VectorXd p;                // refitted parameters (optimiser space)
  std::vector<std::string> labels;  // of p
};

/// Seconds spent on each stage. The missing force and the refits (with their held-out
/// checks) are the sums of their own runs', which run side by side under MPI.
struct StageTimes {
  double nominal_fit = 0, missing_force = 0, screening = 0, refits = 0, heldout = 0,
         second_screening = 0, learned_correction = 0;
};

struct Diagnosis {
  std::string scenario, outdir;
  DiagnoseSettings settings;
  std::vector<Candidate> candidates;
  // Stage 1
  /// The stiffness scan before the nominal fit (empty when not run) and the scale
  /// of the scenario's moduli the fit started from.
  std::vector<ScanPoint> stiffness_scan;
  double stiffness_scale = 1;
  int nominal_evaluations = 0;
  std::vector<NamedValue> nominal_parameters;
  std::string nominal_errors_note;  // as RefitResult::errors_note
  MisfitFigures nominal_train;
  std::vector<ResidualSample> nominal_samples;  // of nominal_train.residual
  std::vector<std::string> marker_names;        // the training objective's markers
  std::vector<HeldOutFigures> nominal_heldout;
  NoiseEstimate noise;
  // Stage 2
  ResidualTables where;
  MissingForce missing_force;  // of the nominal model (ok false when not run)
  // Stage 3
  Ranking ranking;
  /// Per candidate: the held-out ‖h‖² drop its screening step predicts (m², summed
  /// over the held-out motions; NaN when not predicted). Made when more candidates
  /// clear their threshold than are refitted; the refit order then follows it.
  std::vector<double> predicted_heldout_drop;
  bool refit_order_from_heldout = false;
  std::vector<RefitResult> refits;
  // Verdict
  std::string effect = "none";
  std::vector<std::string> verdict_where;
  int accepted = -1;  // index into refits
  /// The learned correction's refit (index into refits; -1 when not run: a named
  /// effect was accepted, or the missing force found nothing beyond noise), and its
  /// signature in strain and rate.
  int learned = -1;
  CorrectionSignature signature;
  /// Screening again with the accepted effect in the model (at its refit): the
  /// first significant candidate there is refitted as a second effect.
  Ranking second_ranking;
  int second_candidate = -1;
  /// The refit of second_candidate with the accepted effect in the model (candidate
  /// -1 when not run), and its id when it passes as the first did ("" otherwise).
  RefitResult second_refit;
  std::string second_effect;
  /// The missing force of the accepted model at its refit: what the effect leaves
  /// unexplained (ok false when not run).
  MissingForce remaining_force;
  std::string fitted_yaml;  // of the accepted model (the nominal one when none)
  bool interrupted = false;
  StageTimes seconds;
};

struct DiagnoseOptions {
  bool resume = false;
  int max_evaluations = 0;  // per fit; 0 = the scenario's
  const std::atomic<bool>* interrupt = nullptr;
  std::function<void(const std::string&)> progress;
};

/// Runs every stage; throws kelvin::Error on bad input. Intermediate results (the
/// nominal and refitted parameters) are kept in outdir/state so that --resume
/// skips what is done.
Diagnosis run_diagnosis(const std::string& scenario_path, const std::string& outdir,
                        const DiagnoseOptions& options);

}  // namespace kelvin
