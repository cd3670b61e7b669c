#pragma once
// The gradient check every extension's test asserts: adjoint, forward sensitivities
// and central differences agree, and the Taylor remainder falls at rate 2.
#include <gtest/gtest.h>

#include "adjoint/fit_problem.hpp"
#include "adjoint/gradient_check.hpp"

namespace kelvin::test {

inline void expect_methods_agree(const GradientCheckReport& r) {
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_LT(r.adjoint_vs_forward, 1e-6) << "adjoint\n" << r.adjoint << "\nforward\n" << r.forward;
  EXPECT_LT(r.adjoint_vs_fd, 1e-4) << "adjoint\n" << r.adjoint << "\nFD\n" << r.finite_difference;
  EXPECT_GE(r.slope, 1.9);
  EXPECT_LE(r.slope, 2.1);
}

/// Checks every parameter of the problem at its start.
inline void expect_gradients_agree(FitProblem& problem) {
  GradientCheckOptions o;
  o.max_parameters = problem.map().size();
  expect_methods_agree(check_gradient(problem, problem.map().initial(), o));
}

}  // namespace kelvin::test
