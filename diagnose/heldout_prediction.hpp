#pragma once
/// \file
/// What a candidate's refit would do on a held-out motion, predicted without the
/// refit: its screening step (the candidate's entries and the fitted ones that
/// compensate for it) applied to the held-out motion's linearised residual. With small
/// capture noise nearly every candidate clears its training threshold (the silicone
/// beam: 11 of 12), and the training score favours observation effects (marker
/// offsets, registration) that do nothing for another motion; the held-out
/// prediction then decides which candidates are worth a refit.
#include <Eigen/Core>
#include <vector>

#include "adjoint/score_screening.hpp"

namespace kelvin {

/// ‖h‖² − ‖h + J_h Δ‖² (m²), Δ the step of `score` on its active entries and the
/// `fitted` entries (score.fitted_step, in that order); h and J_h of the held-out
/// motion at the screening point, on the screening model's parameter map. 0 for a
/// candidate without a step (one the training data cannot see).
double predicted_heldout_drop(const Eigen::VectorXd& h, const Eigen::MatrixXd& jacobian,
                              const CandidateScore& score, const std::vector<int>& fitted);

/// Candidates by decreasing predicted held-out drop (the drops per candidate; NaN:
/// not predicted, those keep their given order after the predicted ones).
std::vector<int> order_by_heldout(const std::vector<int>& candidates,
                                  const std::vector<double>& drop);

}  // namespace kelvin
