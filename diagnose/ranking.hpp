#pragma once
/// \file
/// Greedy orthogonal ranking of candidate effects on the nominal fit's linearised
/// residual (forward selection, as ERR/FROLS do for linear-in-parameter models):
/// the candidate with the largest significant score goes first, and every later one
/// is scored with the directions of those before it projected out, so that two
/// candidates explaining the same residual are not both credited. Significance is
/// the score statistic against the χ² quantile at α / m (m candidates: Bonferroni),
/// with the noise level estimated from the residual's fast part (diagnose/noise).
#include <Eigen/Core>
#include <string>
#include <vector>

#include "adjoint/score_screening.hpp"

namespace kelvin {

struct RankedCandidate {
  int candidate = -1;          // index into the groups passed in
  CandidateScore marginal;     // alone, given the nominal parameters
  CandidateScore conditional;  // given the nominal and every significant one ranked before
  double threshold = 0;        // the χ²(dof) quantile at α / m its statistic must clear
  bool significant = false;    // marginal and conditional statistics both clear it
};

struct ConfoundedPair {
  int a = -1, b = -1;      // indices into the groups
  double correlation = 0;  // largest canonical correlation of their effects
};

struct Ranking {
  std::vector<RankedCandidate> order;  // greedy order
  std::vector<ConfoundedPair> confounded;
  double alpha = 0;
};

/// Pairs whose canonical correlation exceeds this are reported as confounded.
constexpr double kConfoundedCorrelation = 0.9;

Ranking rank_candidates(const Eigen::VectorXd& residual, const Eigen::MatrixXd& jacobian,
                        const std::vector<int>& nominal,
                        const std::vector<std::pair<std::string, std::vector<int>>>& groups,
                        const ScreeningOptions& options, double alpha);

}  // namespace kelvin
