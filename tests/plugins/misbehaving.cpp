// Models that break the contract: one returns NaN stress past a stretch, one
// throws, one writes to an unmapped address. kelvin must report the element and the
// state, and for the crash, which it cannot survive, say where and what is kept.
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

#include "materials/plugin_sdk.hpp"

namespace {

using namespace kelvin;

const std::vector<ParamInfo>& one_param() {
  static const std::vector<ParamInfo> p = {{"mu", "Pa", "shear modulus", 1e4, 0, 1e300, true}};
  return p;
}

/// Linear spring P = μ (F − I) that turns into NaN when tr F > 3.3.
class NanModel final : public Material {
 public:
  std::string name() const override { return "nan-model"; }
  const std::vector<ParamInfo>& params() const override { return one_param(); }
  bool is_viscous() const override { return false; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override {
    const double bad = in.F.trace() > 3.3 ? std::numeric_limits<double>::quiet_NaN() : 0.0;
    if (request & kStress) out.P = in.q[0] * (in.F - Mat3::Identity()) + Mat3::Constant(bad);
    if (request & kTangent) out.dPdF = in.q[0] * Mat9::Identity();
    if (request & kParamDerivative) {
      out.dPdq.resize(9, 1);
      Eigen::Map<Mat3>(out.dPdq.data()) = in.F - Mat3::Identity();
    }
    return true;
  }
};

class ThrowingModel final : public Material {
 public:
  std::string name() const override { return "throwing-model"; }
  const std::vector<ParamInfo>& params() const override { return one_param(); }
  bool is_viscous() const override { return false; }
  bool evaluate(const MaterialPoint&, unsigned, MaterialResponse&) const override {
    throw std::runtime_error("table lookup out of range");
  }
};

/// Linear spring P = μ (F − I) that crashes (SIGSEGV) at element `crash_element`
/// once μ exceeds `crash_above`: a bug that shows only at some trial parameters.
class SegfaultModel final : public Material {
 public:
  std::string name() const override { return "segfault-model"; }
  const std::vector<ParamInfo>& params() const override {
    static const std::vector<ParamInfo> p = {
        {"mu", "Pa", "shear modulus", 1e4, 0, 1e300, true},
        {"crash_above", "Pa", "mu beyond which the model crashes", 1e19, 0, 1e300, true},
        {"crash_element", "1", "element at which it crashes", 0, 0, 1e9, false}};
    return p;
  }
  bool is_viscous() const override { return false; }
  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override {
    if (in.q[0] > in.q[1] && in.element == static_cast<int>(in.q[2])) {
      // An unmapped page, not null: UBSan would stop a null store before the fault.
      volatile std::uintptr_t address = 64;
      *reinterpret_cast<volatile double*>(address) = 1;
    }
    if (request & kStress) out.P = in.q[0] * (in.F - Mat3::Identity());
    if (request & kTangent) out.dPdF = in.q[0] * Mat9::Identity();
    if (request & kParamDerivative) {
      out.dPdq.setZero(9, 3);
      Eigen::Map<Mat3>(out.dPdq.data()) = in.F - Mat3::Identity();
    }
    return true;
  }
};

}  // namespace

KELVIN_EXPORT_MATERIALS(NanModel, ThrowingModel, SegfaultModel)
