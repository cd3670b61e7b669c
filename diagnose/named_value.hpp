#pragma once
/// \file
/// A fitted parameter as the diagnosis reports it.
#include <cmath>
#include <string>

namespace kelvin {

struct NamedValue {
  std::string name;
  double value = 0, std_error = NAN;  // model units
};

}  // namespace kelvin
