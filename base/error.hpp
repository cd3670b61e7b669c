#pragma once
// One exception type for every user-facing failure, below every layer (materials
// included). The message is meant to be printed as it is: it already names the
// file/line/key, element or time.
#include <stdexcept>
#include <string>

namespace kelvin {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A failure of the machine (a disk that cannot be read back), not of the model:
/// a fit ends on it instead of treating it as a failed trial of the parameters.
class IoError : public Error {
 public:
  using Error::Error;
};

}  // namespace kelvin
