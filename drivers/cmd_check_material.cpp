#include <fmt/format.h>

#include <filesystem>
#include <map>

#include "base/error.hpp"
#include "drivers/commands.hpp"
#include "materials/derivative_check.hpp"
#include "materials/material.hpp"
#include "materials/plugin_loader.hpp"

namespace kelvin {
namespace {

std::string range_text(const ParamInfo& p) {
  auto num = [](double v) {
    return std::abs(v) >= 1e299 ? std::string(v < 0 ? "-inf" : "inf") : fmt::format("{:g}", v);
  };
  return fmt::format("{}{}, {}]", p.positive ? "(" : "[", num(p.lower), num(p.upper));
}

void print_model(const Material& m) {
  fmt::print("{} ({}{}{}{})\n", m.name(), m.is_viscous() ? "viscous" : "elastic",
             m.has_energy() ? ", hyperelastic" : "",
             m.state_size() ? fmt::format(", {} state values per element", m.state_size()) : "",
             m.internal_size()
                 ? fmt::format(", {} internal variables per element", m.internal_size())
                 : "");
  for (const auto& p : m.params())
    fmt::print("    {:<10} {:>10g} {:<8} {:<16} {}\n", p.name, p.default_value, p.unit,
               range_text(p), p.description);
}

int run_check(const std::string& target, const std::string& model_name,
              const std::vector<std::string>& sets, double tolerance, std::uint64_t seed) {
  const bool is_plugin =
      target.find('/') != std::string::npos || std::filesystem::path(target).extension() == ".so";
  std::unique_ptr<Material> m =
      is_plugin ? load_plugin_material(target, model_name) : create_material(target, "");
  std::vector<double> q;
  for (const auto& p : m->params()) q.push_back(p.default_value);
  for (const auto& s : sets) {
    const auto eq = s.find('=');
    if (eq == std::string::npos) throw Error("--set expects name=value, got '" + s + "'");
    const std::string key = s.substr(0, eq);
    size_t k = 0;
    while (k < m->params().size() && m->params()[k].name != key) ++k;
    if (k == m->params().size())
      throw Error("model '" + m->name() + "' has no parameter '" + key + "'");
    const std::string text = s.substr(eq + 1);
    char* end = nullptr;
    q[k] = std::strtod(text.c_str(), &end);
    if (text.empty() || *end != '\0')
      throw Error("--set " + key + ": '" + text + "' is not a number");
  }
  print_model(*m);
  std::string values;
  for (size_t k = 0; k < q.size(); ++k)
    values += fmt::format("{}{}={:g}", k ? ", " : "", m->params()[k].name, q[k]);
  fmt::print("checked at {}\n\n", values);

  MaterialCheckOptions opt;
  opt.tolerance = tolerance;
  opt.seed = seed;
  const auto checks = check_material_derivatives(*m, q, opt);
  fmt::print("{:<22} {:<24} {:>12} {:>10}  {}\n", "check", "state", "rel. error", "tolerance", "");
  int failed = 0;
  for (const auto& c : checks) {
    fmt::print("{:<22} {:<24} {:>12.3e} {:>10.1e}  {}\n", c.what, c.state, c.error, c.tolerance,
               c.passed() ? "ok" : "FAIL");
    failed += !c.passed();
  }
  fmt::print("\n{}: {} checks, {} failed\n", m->name(), checks.size(), failed);
  return failed ? kExitRunFailed : kExitOk;
}

}  // namespace

void register_check_material(CLI::App& app, int& exit_code) {
  struct Args {
    std::string target, model;
    std::vector<std::string> sets;
    bool list = false;
    double tolerance = 1e-6;
    std::uint64_t seed = 20261122;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "check-material",
      "Check a material's derivatives by central finite differences (dP/dF, dP/dFdot, dP/dq, "
      "P against the energy; for models with internal variables dP/dz and the evolution law's "
      "df/dF, df/dz, df/dq away from the relaxed state, and f = 0 at it), symmetry, "
      "objectivity and rest state, at random, compressed, stretched and nearly inverted "
      "states. Exits non-zero when a check fails.");
  cmd->add_option("model", args->target,
                  "built-in model name, or the path of a plugin library (.so)");
  cmd->add_option("--model", args->model, "model name inside a plugin exporting several");
  cmd->add_option("--set", args->sets, "parameter value name=value (repeatable)");
  cmd->add_option("--tolerance", args->tolerance, "relative error tolerance (default 1e-6)");
  cmd->add_option("--seed", args->seed, "seed of the random test states");
  cmd->add_flag("--list", args->list, "list the built-in models with their parameters");
  cmd->callback([args, &exit_code] {
    try {
      if (args->list) {
        for (const auto& name : builtin_material_names()) print_model(*create_material(name, ""));
        return;
      }
      if (args->target.empty()) throw Error("give a model name or a plugin path (or --list)");
      exit_code = run_check(args->target, args->model, args->sets, args->tolerance, args->seed);
    } catch (const Error& e) {
      fmt::print(stderr, "error: {}\n", e.what());
      exit_code = kExitInputError;
    }
  });
}

}  // namespace kelvin
