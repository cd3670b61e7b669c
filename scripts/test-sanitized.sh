#!/usr/bin/env bash
# The fast tests of the readers, the scenario checks, the command line, the assembly
# and the gradients, built with AddressSanitizer + UndefinedBehaviorSanitizer in a
# second build directory (build-asan): a memory error or undefined behaviour fails
# the run. The dependencies are scripts/install-deps.sh's.
set -euo pipefail
cd "$(dirname "$0")/.."
TESTS=(test_mesh test_markers test_csv test_capture test_rigid_motion test_cubic_spline
       test_output test_scenario test_scenario_fit test_materials test_assembly
       test_bad_inputs test_cli test_clamp_compliance test_fitted_scenario test_relaxation)
cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DKELVIN_SANITIZE=ON \
  -DKELVIN_BUILD_BENCH=OFF >/dev/null
cmake --build build-asan -j2 --target kelvin "${TESTS[@]}"
# Leaks are not errors here: yaml-cpp and the OpenMP runtime keep static state.
export ASAN_OPTIONS=detect_leaks=0:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1
labels=$(IFS='|'; echo "${TESTS[*]}")
ctest --test-dir build-asan --output-on-failure -j2 -LE long -L "^(${labels})$"
