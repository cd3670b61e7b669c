#pragma once
/// \file
/// What `kelvin fit` keeps on disk while it runs, so that nothing computed is lost:
/// history.csv (one row per evaluation, rewritten atomically after each) and
/// fit-state.yaml (the best parameters so far with the counters `--resume` needs).
#include <Eigen/Core>
#include <string>
#include <vector>

#include "adjoint/parameter_map.hpp"
#include "fit/fit_loop.hpp"

namespace kelvin {

/// history.csv: evaluation, iteration, accepted, ok, objective, misfit, penalty,
/// rms_mm, gradient_norm, seconds, then the model-unit value of each parameter
/// (when there are at most kHistoryParameterColumns of them), then the error.
class FitHistoryFile {
 public:
  static constexpr int kHistoryParameterColumns = 64;
  FitHistoryFile(std::string path, const ParameterMap& map);
  /// Keeps the rows of evaluations 1…`evaluations` of an existing file (for
  /// --resume): a kill between writing the history and the state leaves a row the
  /// state does not count. Throws kelvin::Error when the header belongs to another
  /// parameter map.
  void load_existing(int evaluations);
  void append(const FitRecord& record);  // and rewrite the file
  /// Records of the loaded rows (without parameter vectors), for the report.
  const std::vector<FitRecord>& records() const { return records_; }

 private:
  std::string path_, header_;
  const ParameterMap& map_;
  std::vector<std::string> rows_;
  std::vector<FitRecord> records_;
};

/// The resumable state of a fit.
struct FitState {
  std::string scenario;             // path of the fitted scenario
  std::vector<std::string> labels;  // parameter labels, to refuse a mismatched resume
  Eigen::VectorXd start;            // optimiser-space start of the first run
  Eigen::VectorXd best;             // optimiser-space best so far
  double best_objective = 0, best_rms = 0;
  int evaluations = 0, iterations = 0, failures = 0;
  double seconds = 0;
  double tolerance_scale = 1;  // FitRecord::tolerance_scale of the last evaluation
};

void write_fit_state(const std::string& path, const FitState& state);
/// Throws kelvin::Error naming the file when it is missing or malformed.
FitState read_fit_state(const std::string& path);

}  // namespace kelvin
