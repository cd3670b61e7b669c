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

/// A response (MaterialResponse, InternalResponse) reused across calls: a fresh
/// MaterialResponse zero-fills 171 doubles each time. The first thread to ask gets a
/// plain static (a thread_local in a dlopen'ed module costs a __tls_get_addr call, 3%
/// of a neo-Hookean assembly); any other thread gets its own thread_local, so
/// concurrent evaluation stays safe.
template <class Response>
Response& scratch() {
  static const pthread_t first = pthread_self();
  static Response first_thread;
  if (pthread_equal(pthread_self(), first)) return first_thread;
  thread_local Response other;
  return other;
}

/// Writes an exception's message into the C message buffer.
inline void write_message(const char* what, char* msg, int msg_size) {
  std::strncpy(msg, what, msg_size > 0 ? msg_size - 1 : 0);
  if (msg_size > 0) msg[msg_size - 1] = '\0';
}

/// kelvin's material point from the C one.
inline MaterialPoint material_point(const kelvin_material_point* in) {
  MaterialPoint p;
  p.F = Eigen::Map<const Mat3>(in->F);
  p.Fdot = Eigen::Map<const Mat3>(in->Fdot);
  p.q = in->q;
  p.state = in->state;
  p.internal = in->internal;
  p.element = in->element;
  return p;
}

/// Runs body() (a kelvin_status) with exceptions turned into KELVIN_FAILED and the
/// message: none may cross the C boundary.
template <class Body>
int guarded(char* msg, int msg_size, Body body) noexcept {
  try {
    return body();
  } catch (const std::exception& e) {
    write_message(e.what(), msg, msg_size);
  } catch (...) {
    write_message("unknown exception", msg, msg_size);
  }
  return KELVIN_FAILED;
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
    desc_.evaluate = nullptr;  // set by the registry to per-slot trampolines, as the two below
    desc_.internal_size = model_->internal_size();
    desc_.relaxed_internal = nullptr;
    desc_.evolve = nullptr;
  }
  const Material& model() const { return *model_; }
  kelvin_material_desc& desc() { return desc_; }

  int evaluate(const kelvin_material_point* in, unsigned request, kelvin_material_response* out,
               char* msg, int msg_size) const noexcept {
    return guarded(msg, msg_size, [&] {
      MaterialResponse& r = scratch<MaterialResponse>();
      if (!model_->evaluate(material_point(in), request, r)) return KELVIN_INADMISSIBLE;
      if (out->P) Eigen::Map<Mat3>(out->P) = r.P;
      if (out->dPdF) Eigen::Map<Mat9>(out->dPdF) = r.dPdF;
      if (out->dPdFdot) Eigen::Map<Mat9>(out->dPdFdot) = r.dPdFdot;
      copy(out->dPdq, r.dPdq);
      copy(out->dPdz, r.dPdz);
      if (out->energy) *out->energy = r.energy;
      return KELVIN_OK;
    });
  }

  int relaxed_internal(const double* F, const double* q, double* z, char* msg,
                       int msg_size) const noexcept {
    return guarded(msg, msg_size, [&] {
      model_->relaxed_internal(Eigen::Map<const Mat3>(F), q, z);
      return KELVIN_OK;
    });
  }

  int evolve(const kelvin_material_point* in, unsigned request, kelvin_internal_response* out,
             char* msg, int msg_size) const noexcept {
    return guarded(msg, msg_size, [&] {
      InternalResponse& r = scratch<InternalResponse>();
      model_->evolve(material_point(in), request, r);
      copy(out->rate, r.rate);
      copy(out->dF, r.dF);
      copy(out->dz, r.dz);
      copy(out->dq, r.dq);
      return KELVIN_OK;
    });
  }

 private:
  /// A requested (non-null) output array gets a dynamic-size result's values.
  template <class Matrix>
  static void copy(double* to, const Matrix& from) {
    if (to && from.size()) std::memcpy(to, from.data(), sizeof(double) * from.size());
  }

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

template <int Slot>
int relaxed_trampoline(const double* F, const double* q, double* z, char* msg, int msg_size) {
  return exported()[Slot]->relaxed_internal(F, q, z, msg, msg_size);
}

template <int Slot>
int evolve_trampoline(const kelvin_material_point* in, unsigned request,
                      kelvin_internal_response* out, char* msg, int msg_size) {
  return exported()[Slot]->evolve(in, request, out, msg, msg_size);
}

template <int Slot>
void set_trampolines(kelvin_material_desc& d) {
  d.evaluate = &trampoline<Slot>;
  if (d.internal_size > 0) {
    d.relaxed_internal = &relaxed_trampoline<Slot>;
    d.evolve = &evolve_trampoline<Slot>;
  }
}

template <class... Models, int... Slots>
void register_models(std::integer_sequence<int, Slots...>) {
  (exported().push_back(std::make_unique<Exported>(std::make_unique<Models>())), ...);
  (set_trampolines<Slots>(exported()[Slots]->desc()), ...);
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
