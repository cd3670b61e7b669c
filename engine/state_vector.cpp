#include "engine/state_vector.hpp"

#include <algorithm>
#include <cmath>

namespace kelvin {
namespace {

/// Σ (x w)², and with Count in `weighted` how many w are not zero.
template <bool Count>
realtype weighted_square_sum(N_Vector x, N_Vector w, sunindextype* weighted = nullptr) {
  const sunindextype n = NV_LENGTH_S(x);
  const realtype* a = NV_DATA_S(x);
  const realtype* b = NV_DATA_S(w);
  realtype s0 = 0, s1 = 0, s2 = 0, s3 = 0;
  [[maybe_unused]] sunindextype zeros = 0;
  sunindextype i = 0;
  for (; i + 4 <= n; i += 4) {
    const realtype p0 = a[i] * b[i], p1 = a[i + 1] * b[i + 1];
    const realtype p2 = a[i + 2] * b[i + 2], p3 = a[i + 3] * b[i + 3];
    s0 += p0 * p0;
    s1 += p1 * p1;
    s2 += p2 * p2;
    s3 += p3 * p3;
    if constexpr (Count) zeros += (b[i] == 0) + (b[i + 1] == 0) + (b[i + 2] == 0) + (b[i + 3] == 0);
  }
  for (; i < n; ++i) {
    const realtype p = a[i] * b[i];
    s0 += p * p;
    if constexpr (Count) zeros += b[i] == 0;
  }
  if constexpr (Count) *weighted = n - zeros;
  return (s0 + s1) + (s2 + s3);
}

realtype weighted_square_sum_local(N_Vector x, N_Vector w) {
  return weighted_square_sum<false>(x, w);
}

realtype weighted_rms_norm(N_Vector x, N_Vector w) {
  return std::sqrt(weighted_square_sum<false>(x, w) / static_cast<realtype>(NV_LENGTH_S(x)));
}

/// Components of weight 0 (internal variables that cannot move the body) are
/// outside the norm: it averages over the others only. Counting them nearly doubles
/// the norm's cost (0.82 → 1.48 µs for 2 688 entries), so only states with
/// internal variables use it.
realtype weighted_rms_norm_of_weighted(N_Vector x, N_Vector w) {
  sunindextype weighted = 0;
  const realtype sum = weighted_square_sum<true>(x, w, &weighted);
  return std::sqrt(sum / static_cast<realtype>(std::max<sunindextype>(weighted, 1)));
}

}  // namespace

N_Vector new_state_vector(long size, SUNContext ctx, bool zero_weights) {
  N_Vector v = N_VNew_Serial(static_cast<sunindextype>(size), ctx);
  if (v) {
    v->ops->nvwsqrsumlocal = weighted_square_sum_local;
    v->ops->nvwrmsnorm = zero_weights ? weighted_rms_norm_of_weighted : weighted_rms_norm;
  }
  return v;
}

}  // namespace kelvin
