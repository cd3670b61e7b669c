#pragma once
/// \file
/// What both inverses of static probing share: the elastic term they fit, the
/// grouping of elements into fitted values, the element pairs the smoothness ties,
/// and the derivative of the resisting force with respect to the fitted values,
///   ∂r/∂θ = Σ_e V_e ∂P_e/∂q G_e,
/// which for a law linear in its parameters is the whole force: r = (∂r/∂θ) θ.
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <string>
#include <utility>
#include <vector>

#include "engine/clamp_reaction.hpp"
#include "engine/fem_model.hpp"

namespace kelvin {

enum class ElementGrouping {
  kGlobal,   // one value per parameter
  kRegion,   // one per mesh region
  kElement,  // one per element, with the spatial smoothness
};

/// The model's one elastic term (viscous terms carry no load at rest); throws
/// kelvin::Error when there is none or more than one.
int elastic_term(const FemModel& model);

/// Group of each element and the number of groups.
std::pair<std::vector<int>, int> element_groups(const Mesh& mesh, ElementGrouping grouping);

/// Every node's static equilibrium position under the model's loads at its current
/// parameters; throws kelvin::Error naming `measurement` when there is none.
Eigen::Matrix3Xd static_equilibrium(const FemModel& model, const std::string& measurement);

/// Pairs of elements that share a face.
std::vector<std::pair<int, int>> face_neighbours(const Mesh& mesh);

/// ∂r/∂θ over the free dofs at full positions x, θ the groups' values of `term`'s
/// parameters (column group · nq + k, plus column_offset, in a matrix of `columns`
/// columns). With require_linear, throws kelvin::Error naming the element where
/// P ≠ Σ q ∂P/∂q. Throws naming an element the law finds inadmissible.
Eigen::SparseMatrix<double> force_parameter_jacobian(const FemModel& model, int term,
                                                     const Eigen::Matrix3Xd& x,
                                                     const std::vector<int>& group, int columns,
                                                     int column_offset, bool require_linear);

/// ∂R/∂θ of a pressed probe's reaction (engine/clamp_reaction.hpp) at full positions
/// x: the held rows of the element forces, θ grouped as in force_parameter_jacobian.
Eigen::Matrix3Xd reaction_parameter_jacobian(const FemModel& model, int term,
                                             const ClampReaction& press, const Eigen::Matrix3Xd& x,
                                             const std::vector<int>& group, int columns,
                                             int column_offset = 0);

}  // namespace kelvin
