#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "base/communicator.hpp"
#include "drivers/commands.hpp"
#include "materials/crash_report.hpp"
#ifdef KELVIN_MPI
#include "parallel/mpi_communicator.hpp"
#endif

namespace kelvin {
std::atomic<bool> g_interrupted{false};

std::string prepare_output_dir(const std::string& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
    return fmt::format("-o {}: exists and is not a directory", dir);
  fs::create_directories(dir, ec);
  if (ec) return fmt::format("-o {}: cannot create the directory ({})", dir, ec.message());
  const fs::path probe = fs::path(dir) / fmt::format(".kelvin-write-test.{}", ::getpid());
  {
    std::ofstream out(probe);
    out << "x";
    out.close();
    if (!out) {
      fs::remove(probe, ec);
      return fmt::format("-o {}: cannot write files in the directory", dir);
    }
  }
  fs::remove(probe, ec);
  return "";
}
}  // namespace kelvin

namespace {
void on_signal(int) {
  kelvin::g_interrupted = true;
}

#ifdef KELVIN_MPI
/// The commands that run across ranks (`fit`, `diagnose`); any other runs on one rank.
bool runs_across_ranks(int argc, char** argv, std::string& command) {
  for (int i = 1; i < argc; ++i)
    if (argv[i][0] != '-') {
      command = argv[i];
      return command == "fit" || command == "diagnose";
    }
  return true;  // --help, --version
}
#endif
}  // namespace

int main(int argc, char** argv) {
#ifdef KELVIN_MPI
  // kelvin-mpi: every rank runs the command; rank 0 prints and writes the outputs.
  kelvin::MpiRuntime mpi(argc, argv);
  kelvin::MpiCommunicator comm(&kelvin::g_interrupted);
  kelvin::set_world(&comm);
  if (std::string command; comm.size() > 1 && !runs_across_ranks(argc, argv, command)) {
    if (comm.root())
      std::fprintf(stderr,
                   "error: kelvin-mpi runs `fit` and `diagnose` across ranks; run `%s` on one rank "
                   "(mpirun -np 1, or the serial kelvin)\n",
                   command.c_str());
    return kelvin::kExitInputError;
  }
  if (!comm.root() && !std::freopen("/dev/null", "w", stdout)) return kelvin::kExitRunFailed;
#endif
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
  kelvin::register_diagnose(app, exit_code);
  kelvin::register_probe(app, exit_code);

  kelvin::report_crashes("");
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version exit 0; every invalid command line exits 1, as documented.
    // (Under kelvin-mpi every rank parsed the same line: rank 0 says so.)
    const int code = kelvin::world().root() ? app.exit(e) : e.get_exit_code();
    return code == 0 ? kelvin::kExitOk : kelvin::kExitInputError;
  } catch (const std::exception& e) {
    // A failure no command caught (a file system error writing outputs, say): a
    // message and the run-failed code, never an abort.
    std::fprintf(stderr, "error: %s\n", e.what());
    return kelvin::kExitRunFailed;
  }
  return exit_code;
}
