#pragma once
/// \file
/// Threads of the element loops (OpenMP): every core by default, OMP_NUM_THREADS
/// or set_threads to change it. Results do not depend on the count (ElementSlots).
namespace kelvin {

/// Threads an element loop uses (1 without OpenMP).
int thread_count();
/// Sets it for the element loops that follow (n ≥ 1).
void set_threads(int n);
/// This thread's index within the current element loop (0 outside one).
int thread_index();

}  // namespace kelvin
