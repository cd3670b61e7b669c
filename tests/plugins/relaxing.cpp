// The built-in relaxing branch (materials/maxwell.cpp, compiled into this module)
// exported through the SDK: a plugin with internal variables, which kelvin must
// integrate exactly as it integrates the built-in one.
#include "materials/maxwell.hpp"
#include "materials/plugin_sdk.hpp"

KELVIN_EXPORT_MATERIALS(kelvin::MaxwellBranch)
