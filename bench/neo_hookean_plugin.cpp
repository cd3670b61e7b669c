// The built-in neo-Hookean model compiled as a plugin, so that bench_materials can
// measure what the plugin boundary (C ABI, copies, finiteness checks) costs.
#include "materials/neo_hookean.hpp"
#include "materials/plugin_sdk.hpp"

KELVIN_EXPORT_MATERIALS(kelvin::NeoHookean)
