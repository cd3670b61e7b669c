#include "materials/plugin_loader.hpp"

#include <dlfcn.h>

#include <cmath>
#include <sstream>

#include "base/error.hpp"
#include "materials/crash_report.hpp"
#include "materials/plugin_abi.h"

namespace kelvin {
namespace {

/// A dlopen'ed plugin; closed when the last model using it is destroyed.
struct Library {
  std::string path;
  void* handle = nullptr;
  const kelvin_material_desc* descs = nullptr;
  int count = 0;
  ~Library() {
    if (handle) dlclose(handle);
  }
};

std::shared_ptr<Library> open_library(const std::string& path) {
  auto lib = std::make_shared<Library>();
  lib->path = path;
  lib->handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!lib->handle) {
    const char* err = dlerror();
    throw Error("cannot load material plugin " + path + ": " + (err ? err : "unknown error"));
  }
  auto version_fn = reinterpret_cast<kelvin_plugin_abi_version_fn>(
      dlsym(lib->handle, "kelvin_plugin_abi_version"));
  if (!version_fn)
    throw Error("material plugin " + path +
                " does not export kelvin_plugin_abi_version(): is it a kelvin material plugin? "
                "(build it with kelvin_add_material_plugin and KELVIN_EXPORT_MATERIALS)");
  const std::uint32_t version = version_fn();
  if (version != KELVIN_PLUGIN_ABI_VERSION)
    throw Error("material plugin " + path + " was built for kelvin plugin ABI " +
                abi_version_string(version) + ", but this kelvin has ABI " +
                abi_version_string(KELVIN_PLUGIN_ABI_VERSION) +
                ": rebuild the plugin against this kelvin's SDK");
  auto materials_fn =
      reinterpret_cast<kelvin_plugin_materials_fn>(dlsym(lib->handle, "kelvin_plugin_materials"));
  if (!materials_fn)
    throw Error("material plugin " + path + " does not export kelvin_plugin_materials()");
  lib->count = materials_fn(&lib->descs);
  if (lib->count <= 0 || !lib->descs)
    throw Error("material plugin " + path + " exports no material model");
  return lib;
}

std::string format_tensor(const double* a) {
  std::ostringstream s;
  s.precision(6);
  s << "[";
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) s << (j ? " " : "") << a[i + 3 * j];
    s << (i < 2 ? "; " : "]");
  }
  return s.str();
}

class PluginMaterial final : public Material {
 public:
  PluginMaterial(std::shared_ptr<Library> lib, const kelvin_material_desc* d)
      : lib_(std::move(lib)),
        d_(d),
        who_("plugin material '" + std::string(d->name) + "' (" + lib_->path + ")") {
    for (int k = 0; k < d->num_params; ++k) {
      const kelvin_param_info& p = d->params[k];
      params_.push_back({p.name, p.unit ? p.unit : "", p.description ? p.description : "",
                         p.default_value, p.lower, p.upper, p.positive != 0});
    }
    if (d->state_size > 0 && d->default_state)
      state_.assign(d->default_state, d->default_state + d->state_size);
    if (d->internal_size < 0 || (d->internal_size > 0 && (!d->relaxed_internal || !d->evolve)))
      throw Error(who_ + " declares " + std::to_string(d->internal_size) +
                  " internal variables but not both relaxed_internal and evolve");
  }
  std::string name() const override { return d_->name; }
  const std::vector<ParamInfo>& params() const override { return params_; }
  bool is_viscous() const override { return d_->is_viscous != 0; }
  bool has_energy() const override { return d_->has_energy != 0; }
  int state_size() const override { return d_->state_size; }
  std::vector<double> default_state() const override { return state_; }
  int internal_size() const override { return d_->internal_size; }

  void relaxed_internal(const Mat3& F, const double* q, double* z) const override {
    char msg[512];
    msg[0] = '\0';
    enter_plugin_call(who_.c_str(), -1);
    const int status = d_->relaxed_internal(F.data(), q, z, msg, sizeof msg);
    leave_plugin_call();
    if (status != KELVIN_OK)
      throw Error(who_ + ": its relaxed internal state failed at F = " + format_tensor(F.data()) +
                  ": " + (msg[0] ? std::string(msg) : "no message"));
    check_finite("the relaxed internal state", z, d_->internal_size, F.data(), -1);
  }

  void evolve(const MaterialPoint& in, unsigned request, InternalResponse& out) const override {
    const int m = d_->internal_size, nq = d_->num_params;
    out.rate.resize(m);
    if (request & kTangent) {
      out.dF.resize(m, 9);
      out.dz.resize(m, m);
    }
    if (request & kParamDerivative) out.dq.resize(m, nq);
    kelvin_material_point p{in.F.data(), in.Fdot.data(), in.q, in.state, in.internal, in.element};
    kelvin_internal_response r{out.rate.data(), (request & kTangent) ? out.dF.data() : nullptr,
                               (request & kTangent) ? out.dz.data() : nullptr,
                               (request & kParamDerivative) ? out.dq.data() : nullptr};
    char msg[512];
    msg[0] = '\0';
    enter_plugin_call(who_.c_str(), in.element);
    const int status = d_->evolve(&p, request, &r, msg, sizeof msg);
    leave_plugin_call();
    if (status != KELVIN_OK)
      throw Error(where(in) + ": its internal variables' law failed: " +
                  (msg[0] ? std::string(msg) : "no message"));
    check_finite("the internal variables' rate", r.rate, m, in.F.data(), in.element);
    check_finite("d(rate)/dF", r.dF, 9L * m, in.F.data(), in.element);
    check_finite("d(rate)/dz", r.dz, static_cast<long>(m) * m, in.F.data(), in.element);
    check_finite("d(rate)/dq", r.dq, static_cast<long>(m) * nq, in.F.data(), in.element);
  }

  bool evaluate(const MaterialPoint& in, unsigned request, MaterialResponse& out) const override {
    kelvin_material_point p{in.F.data(), in.Fdot.data(), in.q, in.state, in.internal, in.element};
    const int nq = d_->num_params, m = d_->internal_size;
    if (request & kParamDerivative) out.dPdq.resize(9, nq);
    const bool dPdz = (request & kTangent) && m > 0;
    if (dPdz) out.dPdz.resize(9, m);
    kelvin_material_response r{
        (request & kStress) ? out.P.data() : nullptr,
        (request & kTangent) ? out.dPdF.data() : nullptr,
        (request & kRateTangent) ? out.dPdFdot.data() : nullptr,
        (request & kParamDerivative) ? out.dPdq.data() : nullptr,
        dPdz ? out.dPdz.data() : nullptr,
        (request & kEnergy) ? &out.energy : nullptr,
    };
    char msg[512];
    msg[0] = '\0';
    enter_plugin_call(who_.c_str(), in.element);
    const int status = d_->evaluate(&p, request, &r, msg, sizeof msg);
    leave_plugin_call();
    if (status == KELVIN_INADMISSIBLE) return false;
    if (status != KELVIN_OK)
      throw Error(where(in) + " failed: " + (msg[0] ? std::string(msg) : "no message"));
    // x·0 is NaN exactly when x is NaN or ±Inf, so one sum checks a whole array;
    // Eigen's packet reduction vectorises it (an element-wise loop cost 7% of a
    // neo-Hookean assembly).
    auto check = [&](const char* what, const double* a, long size) {
      if (!a) return;
      if (!std::isfinite((Eigen::Map<const Eigen::ArrayXd>(a, size) * 0.0).sum()))
        throw Error(where(in) + " returned a non-finite value in " + what);
    };
    check("P", r.P, 9);
    check("dP/dF", r.dPdF, 81);
    check("dP/dFdot", r.dPdFdot, 81);
    check("dP/dq", r.dPdq, 9L * nq);
    check("dP/dz", r.dPdz, 9L * m);
    check("the energy", r.energy, 1);
    return true;
  }

 private:
  void check_finite(const char* what, const double* a, long size, const double* F,
                    int element) const {
    if (a && !std::isfinite((Eigen::Map<const Eigen::ArrayXd>(a, size) * 0.0).sum()))
      throw Error(who_ + " at element " + std::to_string(element) +
                  " with F = " + format_tensor(F) + " returned a non-finite value in " + what);
  }

  std::string where(const MaterialPoint& in) const {
    return "plugin material '" + name() + "' (" + lib_->path + ") at element " +
           std::to_string(in.element) + " with F = " + format_tensor(in.F.data()) +
           ", Fdot = " + format_tensor(in.Fdot.data());
  }

  std::shared_ptr<Library> lib_;
  const kelvin_material_desc* d_;
  std::string who_;  // for the crash report
  std::vector<ParamInfo> params_;
  std::vector<double> state_;
};

}  // namespace

std::string abi_version_string(std::uint32_t v) {
  return std::to_string(v >> 16) + "." + std::to_string((v >> 8) & 0xff) + "." +
         std::to_string(v & 0xff);
}

std::vector<std::string> plugin_material_names(const std::string& path) {
  auto lib = open_library(path);
  std::vector<std::string> names;
  for (int k = 0; k < lib->count; ++k) names.push_back(lib->descs[k].name);
  return names;
}

std::unique_ptr<Material> load_plugin_material(const std::string& path, const std::string& name) {
  auto lib = open_library(path);
  if (name.empty() && lib->count == 1) return std::make_unique<PluginMaterial>(lib, &lib->descs[0]);
  std::string available;
  for (int k = 0; k < lib->count; ++k) {
    if (name == lib->descs[k].name) return std::make_unique<PluginMaterial>(lib, &lib->descs[k]);
    available += (k ? ", " : "") + std::string(lib->descs[k].name);
  }
  throw Error("material plugin " + path + " has no model '" + name + "' (it exports: " + available +
              ")");
}

}  // namespace kelvin
