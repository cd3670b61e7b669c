#pragma once
/// \file
/// The serial N_Vector for IDAS states, forward and adjoint, with faster weighted
/// RMS norms. IDAS takes about eleven per step; SUNDIALS' serial loop carries one
/// dependent sum that the compiler may not reorder, which made the norms 12 % of
/// a step on the 120-tet benchmark bar (270 entries). Four independent partial
/// sums remove that chain; the norm differs from SUNDIALS' in rounding only.
#include <nvector/nvector_serial.h>

namespace kelvin {

/// N_VNew_Serial(size, ctx) with the norms replaced; clones inherit them. With
/// `zero_weights` the WRMS norm averages over the components of non-zero weight only
/// (a state with internal variables that may weigh nothing).
N_Vector new_state_vector(long size, SUNContext ctx, bool zero_weights = false);

}  // namespace kelvin
