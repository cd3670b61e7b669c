#pragma once
/// \file
/// Finite-difference verification of a material's derivatives — one checker for
/// every model (built-in or plugin), used by the tests and by
/// `kelvin check-material`. Central differences with a sweep of step sizes; the
/// best relative error over the sweep is reported, as in Ceres' gradient_checker.
#include <random>
#include <string>
#include <vector>

#include "materials/material.hpp"

namespace kelvin {

struct DerivativeCheck {
  std::string what;   // e.g. "dP/dF", "P = dΨ/dF", "objectivity"
  std::string state;  // e.g. "compression J=0.45"
  double error = 0;   // best relative error over the step sweep
  double tolerance = 0;
  bool passed() const { return error <= tolerance; }
};

struct MaterialCheckOptions {
  double tolerance = 1e-6;
  int random_states = 4;  // random deformations near identity, on top of the fixed set
  std::uint64_t seed = 20261122;
};

/// A set of test states: random, strong compression, strong stretch, shear and
/// near-inversion deformation gradients, each with a random rate.
struct MaterialState {
  std::string label;
  Mat3 F, Fdot;
};
std::vector<MaterialState> material_test_states(const MaterialCheckOptions& options);

/// Runs every applicable check of `material` with parameters q (params() order).
std::vector<DerivativeCheck> check_material_derivatives(const Material& material,
                                                        const std::vector<double>& q,
                                                        const MaterialCheckOptions& options = {});

}  // namespace kelvin
