#include "materials/drag.hpp"

namespace kelvin {

const std::vector<ParamInfo>& Drag::params() const {
  static const std::vector<ParamInfo> p = {
      {"c", "1/s", "drag per unit mass: force -c rho v per volume", 0.0, 0, 1e300, false},
  };
  return p;
}

bool Drag::evaluate(const MaterialPoint&, unsigned request, MaterialResponse& out) const {
  if (request & kStress) out.P.setZero();
  if (request & kTangent) out.dPdF.setZero();
  if (request & kRateTangent) out.dPdFdot.setZero();
  if (request & kParamDerivative) out.dPdq.setZero(9, 1);
  if (request & kEnergy) out.energy = 0;
  return true;
}

}  // namespace kelvin
