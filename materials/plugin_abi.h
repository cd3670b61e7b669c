/* kelvin material plugin ABI — plain C, so that a plugin built against one kelvin
 * keeps working when kelvin's C++ classes change. A plugin is a shared library
 * exporting two symbols:
 *
 *   uint32_t kelvin_plugin_abi_version(void);        // must return KELVIN_PLUGIN_ABI_VERSION
 *   int kelvin_plugin_materials(const kelvin_material_desc** out);  // number of models
 *
 * C++ authors do not write these by hand: see plugin_sdk.hpp.
 * Tensors are 3×3 column-major (index i + 3j); derivative arrays are 9×9 or 9×nq,
 * column-major. Version = major << 16 | minor << 8 | patch; kelvin refuses any other
 * version than its own. */
#ifndef KELVIN_PLUGIN_ABI_H
#define KELVIN_PLUGIN_ABI_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define KELVIN_PLUGIN_ABI_MAJOR 2
#define KELVIN_PLUGIN_ABI_MINOR 0
#define KELVIN_PLUGIN_ABI_PATCH 0
#define KELVIN_PLUGIN_ABI_VERSION                                                \
  ((uint32_t)((KELVIN_PLUGIN_ABI_MAJOR << 16) | (KELVIN_PLUGIN_ABI_MINOR << 8) | \
              KELVIN_PLUGIN_ABI_PATCH))

typedef struct kelvin_param_info {
  const char* name;
  const char* unit;
  const char* description;
  double default_value, lower, upper;
  int positive; /* strictly positive: the fitter may optimise its logarithm */
} kelvin_param_info;

typedef struct kelvin_material_point {
  const double* F;        /* 9 */
  const double* Fdot;     /* 9 */
  const double* q;        /* num_params */
  const double* state;    /* state_size, or NULL */
  const double* internal; /* internal_size, or NULL (a material check: relaxed at rest) */
  int element;
} kelvin_material_point;

/* Requested outputs are non-NULL. */
typedef struct kelvin_material_response {
  double* P;       /* 9 */
  double* dPdF;    /* 81 */
  double* dPdFdot; /* 81 */
  double* dPdq;    /* 9 × num_params */
  double* dPdz;    /* 9 × internal_size, with the tangent of a model with internal variables */
  double* energy;  /* 1 */
} kelvin_material_response;

/* The internal variables' evolution z' = f(F, z; q); requested outputs are non-NULL. */
typedef struct kelvin_internal_response {
  double* rate; /* internal_size */
  double* dF;   /* internal_size × 9 */
  double* dz;   /* internal_size × internal_size */
  double* dq;   /* internal_size × num_params */
} kelvin_internal_response;

enum kelvin_status {
  KELVIN_OK = 0,
  KELVIN_INADMISSIBLE = 1, /* e.g. det F <= 0: the solver backs off */
  KELVIN_FAILED = 2        /* an error; the message buffer says why */
};

typedef struct kelvin_material_desc {
  const char* name;
  int num_params;
  const kelvin_param_info* params;
  int is_viscous;
  int has_energy;
  int state_size;
  const double* default_state; /* state_size values */
  /* Returns a kelvin_status; on KELVIN_FAILED writes a message to msg (msg_size bytes). */
  int (*evaluate)(const kelvin_material_point* in, unsigned request, kelvin_material_response* out,
                  char* msg, int msg_size);
  /* Internal variables per element, integrated with the motion (0: none, and the two
   * functions below may be NULL): the state relaxed at F (f = 0 with F held), and the
   * evolution law. Both return a kelvin_status. */
  int internal_size;
  int (*relaxed_internal)(const double* F, const double* q, double* z, char* msg, int msg_size);
  int (*evolve)(const kelvin_material_point* in, unsigned request, kelvin_internal_response* out,
                char* msg, int msg_size);
} kelvin_material_desc;

typedef uint32_t (*kelvin_plugin_abi_version_fn)(void);
typedef int (*kelvin_plugin_materials_fn)(const kelvin_material_desc** out);

#ifdef __cplusplus
}
#endif

#endif /* KELVIN_PLUGIN_ABI_H */
