#include <csignal>
#include <cstdio>

#include "drivers/commands.hpp"

namespace kelvin {
std::atomic<bool> g_interrupted{false};
}

namespace {
void on_signal(int) {
  kelvin::g_interrupted = true;
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "kelvin: fit visco-elastic FEM models to captured motion of soft objects, and explain the "
      "remaining sim-to-real gap"};
  app.set_version_flag("--version", "kelvin 0.1.0");
  app.require_subcommand(1);
  int exit_code = kelvin::kExitOk;
  kelvin::register_simulate(app, exit_code);
  kelvin::register_check_material(app, exit_code);
  kelvin::register_gradcheck(app, exit_code);
  kelvin::register_fit(app, exit_code);
  kelvin::register_capture(app, exit_code);

  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  return exit_code;
}
