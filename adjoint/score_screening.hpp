#pragma once
/// \file
/// Screening of candidate effects without refitting them (the first step of the
/// gap diagnosis's "which"): at the nominal fit, with every candidate's parameters φ
/// at their nominal values, the score (Lagrange-multiplier) statistic of each
/// candidate from the Gauss–Newton system r, J = [J_θ J_φ]:
///   LM = gᵀ (J_φᵀ P J_φ)⁻¹ g / σ̂²,  g = J_φᵀ P r,  P = I − J_θ J_θ⁺,
/// the directions of the fitted parameters θ projected out, σ̂² = ‖r‖² / (N − n_θ).
/// Without the effect LM is χ²(n_φ)-distributed; gᵀ(J_φᵀ P J_φ)⁻¹ g is the predicted
/// drop of ‖r‖² when φ is fitted (one Gauss–Newton step).
#include <Eigen/Core>
#include <string>
#include <vector>

namespace kelvin {

struct CandidateScore {
  std::string name;
  std::vector<int> entries;     // of p
  std::vector<int> active;      // the entries the step moves (see nonnegative)
  Eigen::VectorXd step;         // Gauss–Newton Δp of `active` (p units)
  Eigen::VectorXd fitted_step;  // with it, the fitted entries' Δp (p units, `fitted` order)
  int dof = 0;                  // n_φ: active entries
  double statistic = 0;         // LM
  double p_value = 1;           // P(χ²(dof) ≥ LM)
  double predicted_drop = 0;    // of ‖r‖² (m²)
  double rms_before = 0, predicted_rms = 0;  // per coordinate (m)
  std::string error;  // a candidate the data cannot see (J_φ in span of J_θ)
};

struct ScreeningOptions {
  /// σ² (m²) of the statistic; 0: ‖r‖² / (N − n_θ), which a model error inflates.
  double noise_variance = 0;
  /// Entries of p at a lower bound (a nested modulus at 0): a step that would lower
  /// one is not taken; the candidate is scored on the others (an active set).
  std::vector<int> nonnegative;
  /// Fitted entries the step keeps where they are (the data cannot place them, see
  /// unresolved_entries): their directions are still projected out of the score.
  std::vector<int> held;
};

/// Scores of `candidates` (named groups of entries of p) given the entries of p
/// that were fitted; r and J as from gauss_newton_system.
std::vector<CandidateScore> score_candidates(
    const Eigen::VectorXd& residual, const Eigen::MatrixXd& jacobian,
    const std::vector<int>& fitted,
    const std::vector<std::pair<std::string, std::vector<int>>>& candidates,
    const ScreeningOptions& options = {});

/// The largest canonical correlation between the effects of two groups of entries
/// on r once the fitted directions are projected out: the cosine of the smallest
/// angle between span(P J_a) and span(P J_b). Near 1 the data cannot tell a from b.
double confounding(const Eigen::MatrixXd& jacobian, const std::vector<int>& fitted,
                   const std::vector<int>& a, const std::vector<int>& b);

/// P(χ²(k) ≥ x): the regularised upper incomplete gamma function Q(k/2, x/2).
double chi_square_survival(double x, int k);
/// The x with P(χ²(k) ≥ x) = p (0 < p < 1).
double chi_square_quantile(double p, int k);

}  // namespace kelvin
