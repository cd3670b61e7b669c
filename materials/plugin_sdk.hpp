#pragma once
/// \file
/// Writing a material plugin in C++: derive from kelvin::Material exactly as the
/// built-in models do, then export the classes with one line:
///
///   KELVIN_EXPORT_MATERIALS(MyModel, MyOtherModel)
///
/// The macro generates the two C entry points of plugin_abi.h. Only plain C data
/// crosses the library boundary; exceptions thrown by a model are caught here and
/// reported to kelvin as KELVIN_FAILED with their message.
#include <pthread.h>

#include <cstring>
#include <exception>
#include <memory>
#include <string>
#include <vector>

#include "materials/material.hpp"
#include "materials/plugin_abi.h"

namespace kelvin::plugin {

/// Response reused across calls: a fresh one zero-fills 171 doubles each time.
/// The first evaluating thread gets a plain static (a thread_local in a dlopen'ed
/// module costs a __tls_get_addr call, 3% of a neo-Hookean assembly); any other
/// thread gets its own thread_local, so concurrent evaluation stays safe.
inline MaterialResponse& scratch_response() {
  static const pthread_t first = pthread_self();
  static MaterialResponse first_thread;
  if (pthread_equal(pthread_self(), first)) return first_thread;
  thread_local MaterialResponse other;
  return other;
}

/// Owns one model and its C description (the strings live as long as the plugin).
class Exported {
 public:
  explicit Exported(std::unique_ptr<Material> m) : model_(std::move(m)) {
    name_ = model_->name();
    for (const auto& p : model_->params())
      params_.push_back({p.name.c_str(), p.unit.c_str(), p.description.c_str(), p.default_value,
                         p.lower, p.upper, p.positive ? 1 : 0});
    state_ = model_->default_state();
    desc_.name = name_.c_str();
    desc_.num_params = static_cast<int>(params_.size());
    desc_.params = params_.data();
    desc_.is_viscous = model_->is_viscous() ? 1 : 0;
    desc_.has_energy = model_->has_energy() ? 1 : 0;
    desc_.state_size = model_->state_size();
    desc_.default_state = state_.data();
    desc_.evaluate = nullptr;  // set by the registry to a per-slot trampoline
  }
  const Material& model() const { return *model_; }
  kelvin_material_desc& desc() { return desc_; }

  int evaluate(const kelvin_material_point* in, unsigned request, kelvin_material_response* out,
               char* msg, int msg_size) const noexcept {
    try {
      MaterialPoint p;
      p.F = Eigen::Map<const Mat3>(in->F);
      p.Fdot = Eigen::Map<const Mat3>(in->Fdot);
      p.q = in->q;
      p.state = in->state;
      p.element = in->element;
      MaterialResponse& r = scratch_response();
      if (!model_->evaluate(p, request, r)) return KELVIN_INADMISSIBLE;
      if (out->P) Eigen::Map<Mat3>(out->P) = r.P;
      if (out->dPdF) Eigen::Map<Mat9>(out->dPdF) = r.dPdF;
      if (out->dPdFdot) Eigen::Map<Mat9>(out->dPdFdot) = r.dPdFdot;
      if (out->dPdq && r.dPdq.size())
        std::memcpy(out->dPdq, r.dPdq.data(), sizeof(double) * r.dPdq.size());
      if (out->energy) *out->energy = r.energy;
      return KELVIN_OK;
    } catch (const std::exception& e) {
      std::strncpy(msg, e.what(), msg_size > 0 ? msg_size - 1 : 0);
      if (msg_size > 0) msg[msg_size - 1] = '\0';
    } catch (...) {
      std::strncpy(msg, "unknown exception", msg_size > 0 ? msg_size - 1 : 0);
      if (msg_size > 0) msg[msg_size - 1] = '\0';
    }
    return KELVIN_FAILED;
  }

 private:
  std::unique_ptr<Material> model_;
  std::string name_;
  std::vector<kelvin_param_info> params_;
  std::vector<double> state_;
  kelvin_material_desc desc_{};
};

/// The models of this plugin, in export order.
inline std::vector<std::unique_ptr<Exported>>& exported() {
  static std::vector<std::unique_ptr<Exported>> models;
  return models;
}

template <int Slot>
int trampoline(const kelvin_material_point* in, unsigned request, kelvin_material_response* out,
               char* msg, int msg_size) {
  return exported()[Slot]->evaluate(in, request, out, msg, msg_size);
}

template <class... Models, int... Slots>
void register_models(std::integer_sequence<int, Slots...>) {
  (exported().push_back(std::make_unique<Exported>(std::make_unique<Models>())), ...);
  ((exported()[Slots]->desc().evaluate = &trampoline<Slots>), ...);
}

template <class... Models>
int export_models(const kelvin_material_desc** out) {
  static std::vector<kelvin_material_desc> descs = [] {
    register_models<Models...>(std::make_integer_sequence<int, sizeof...(Models)>());
    std::vector<kelvin_material_desc> d;
    for (auto& e : exported()) d.push_back(e->desc());
    return d;
  }();
  *out = descs.data();
  return static_cast<int>(descs.size());
}

}  // namespace kelvin::plugin

#define KELVIN_EXPORT_MATERIALS(...)                                                           \
  extern "C" __attribute__((visibility("default"))) uint32_t kelvin_plugin_abi_version(void) { \
    return KELVIN_PLUGIN_ABI_VERSION;                                                          \
  }                                                                                            \
  extern "C" __attribute__((visibility("default"))) int kelvin_plugin_materials(               \
      const kelvin_material_desc** out) {                                                      \
    try {                                                                                      \
      return ::kelvin::plugin::export_models<__VA_ARGS__>(out);                                \
    } catch (...) {                                                                            \
      return -1;                                                                               \
    }                                                                                          \
  }
