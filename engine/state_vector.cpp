#include "engine/state_vector.hpp"

#include <cmath>

namespace kelvin {
namespace {

realtype weighted_square_sum(N_Vector x, N_Vector w) {
  const sunindextype n = NV_LENGTH_S(x);
  const realtype* a = NV_DATA_S(x);
  const realtype* b = NV_DATA_S(w);
  realtype s0 = 0, s1 = 0, s2 = 0, s3 = 0;
  sunindextype i = 0;
  for (; i + 4 <= n; i += 4) {
    const realtype p0 = a[i] * b[i], p1 = a[i + 1] * b[i + 1];
    const realtype p2 = a[i + 2] * b[i + 2], p3 = a[i + 3] * b[i + 3];
    s0 += p0 * p0;
    s1 += p1 * p1;
    s2 += p2 * p2;
    s3 += p3 * p3;
  }
  for (; i < n; ++i) {
    const realtype p = a[i] * b[i];
    s0 += p * p;
  }
  return (s0 + s1) + (s2 + s3);
}

realtype weighted_rms_norm(N_Vector x, N_Vector w) {
  return std::sqrt(weighted_square_sum(x, w) / static_cast<realtype>(NV_LENGTH_S(x)));
}

}  // namespace

N_Vector new_state_vector(long size, SUNContext ctx) {
  N_Vector v = N_VNew_Serial(static_cast<sunindextype>(size), ctx);
  if (v) {
    v->ops->nvwsqrsumlocal = weighted_square_sum;
    v->ops->nvwrmsnorm = weighted_rms_norm;
  }
  return v;
}

}  // namespace kelvin
