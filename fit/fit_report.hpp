#pragma once
/// \file
/// The report of `kelvin fit` for people: report.md with the parameter table
/// (start, fitted, standard error, bounds), RMS before/after overall and per
/// marker, the stopping reason, and SVG plots of the objective over evaluations,
/// observed vs simulated tracks of the worst and best markers, and the L-curve.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "fit/fit_loop.hpp"

namespace kelvin {

/// Observed and simulated positions of one marker at the observed frame times.
struct TrackPlot {
  std::string experiment;  // scenario name of the captured motion
  std::string marker;
  std::vector<double> t;                 // observed frame times (s)
  Eigen::Matrix3Xd observed;             // 3 × frames, NaN where occluded
  Eigen::Matrix3Xd before, after;        // simulated with the start / fitted parameters
  double rms_before = 0, rms_after = 0;  // m
};

struct MarkerRms {
  std::string experiment, marker;
  double before = 0, after = 0;  // m
};

/// A shape target's RMS distance over its coordinates, with the start and the
/// fitted parameters.
struct TargetRms {
  std::string experiment, target;
  double time = 0;  // s
  int coordinates = 0;
  double before = 0, after = 0;  // m
};

struct FitReportData {
  std::string title;          // scenario name
  std::string scenario_path;  // the input scenario
  std::string algorithm, gradient_method, stop_reason;
  int evaluations = 0, failures = 0;
  double seconds = 0;
  bool interrupted = false;

  /// Per parameter entry (model units). std_error is empty when not computed.
  std::vector<std::string> labels;
  Eigen::VectorXd initial, fitted, std_error, lower, upper;
  double noise_sigma = 0;  // estimated marker noise per coordinate (m); 0 if unknown

  double rms_before = 0, rms_after = 0;  // m, over all experiments
  std::vector<MarkerRms> markers;
  std::vector<TargetRms> targets;
  std::vector<TrackPlot> tracks;  // what to plot (e.g. the worst and best markers)
  std::vector<FitRecord> history;
  std::vector<LcurvePoint> lcurve;
  /// Further Markdown sections appended verbatim (e.g. a coarsening table).
  std::vector<std::string> extra_sections;
  /// Other output files to list, relative to the output directory.
  std::vector<std::string> files;
};

/// Writes report.md and its SVG plots (objective.svg, track-<n>.svg, lcurve.svg)
/// into `outdir`, every file atomically. Returns the path of report.md.
std::string write_fit_report(const std::string& outdir, const FitReportData& data);

}  // namespace kelvin
