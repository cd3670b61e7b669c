// Inputs that once crashed, hung or were silently misread (issue: reliability),
// each now a clear error with a non-zero exit, or read as meant.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <thread>

#include "base/error.hpp"
#include "engine/csv.hpp"
#include "test_support.hpp"
#include "yaml/scenario.hpp"
#include "yaml/scenario_simulation.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;
using test::run_kelvin;

const std::string kBar = R"(
name: bar
mesh: { generate: box, lo: [0, 0, 0], hi: [0.1, 0.02, 0.02], element_size: 0.01 }
material:
  density: 1000
  elastic: { model: neo-hookean, lambda: 1.0e5, mu: 1.0e5 }
gravity: [0, 0, -9.81]
clamps:
  - { name: wall, select: { plane: { axis: x, at: 0 } } }
)";

std::string scenario(const fs::path& dir, const std::string& name, const std::string& tail) {
  const fs::path p = dir / (name + ".yaml");
  test::write_text(p, kBar + tail);
  return p.string();
}

/// kBar with its generated mesh replaced by `mesh` (a YAML flow mapping).
std::string bar_with_mesh(const std::string& mesh) {
  std::string bar = kBar;
  const size_t at = bar.find("{ generate: box");
  return bar.replace(at, bar.find('\n', at) - at, mesh);
}

/// `read` must throw kelvin::Error with `part` in its message.
template <class Read>
void expect_read_error(Read read, const std::string& part) {
  try {
    read();
    ADD_FAILURE() << "accepted; expected an error saying: " << part;
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
  }
}

void expect_input_error(const std::string& args, const std::string& part) {
  const auto r = run_kelvin(args);
  EXPECT_EQ(r.exit_code, 1) << args << "\n" << r.out;
  EXPECT_NE(r.out.find(part), std::string::npos) << args << "\n" << r.out;
  EXPECT_EQ(r.out.find("terminate"), std::string::npos) << r.out;
}

}  // namespace

// An end time or an output rate that would schedule more frames than memory holds
// (1e308 s once made a non-finite floor cast, and 1e12 Hz a 16 GB allocation).
TEST(BadInputs, TooManyOutputFramesAreRefusedAtTheTimeKey) {
  const fs::path dir = test::scratch("bad-time");
  const auto out = (dir / "out").string();
  expect_input_error("simulate " + scenario(dir, "end", "time: { end: 1.0e308 }\n") + " -o " + out,
                     "end.yaml:10:7: time: 1e+308 s at an output rate of 100 Hz");
  expect_input_error(
      "simulate " + scenario(dir, "rate", "time: { end: 1, output_rate: 1.0e12 }\n") + " -o " + out,
      "marker frames, more than the 1e+07 a run can hold");
  expect_input_error(
      "simulate " + scenario(dir, "vtu", "time: { end: 10, vtu_rate: 1.0e5 }\n") + " -o " + out,
      "VTU frames");
  const std::string ok = scenario(dir, "ok", "time: { end: 0.01 }\n");
  expect_input_error("simulate " + ok + " --end 1e308 -o " + out, "--end 1e+308:");
  expect_input_error("simulate " + ok + " --end nan -o " + out, "must be a positive finite number");
  expect_input_error("simulate " + ok + " --end -1 -o " + out, "must be a positive finite number");
}

TEST(BadInputs, OutputsThatCannotBeWrittenAreInputErrors) {
  const fs::path dir = test::scratch("bad-output");
  const std::string ok = scenario(dir, "ok", "time: { end: 0.01 }\n");
  test::write_text(dir / "a-file", "x");
  expect_input_error("simulate " + ok + " -o " + (dir / "a-file").string(),
                     "exists and is not a directory");
  expect_input_error("simulate " + ok + " -o /proc/kelvin-out", "-o /proc/kelvin-out: cannot");
}

TEST(BadInputs, ADirectoryOrAHugeFileIsNotAScenario) {
  const fs::path dir = test::scratch("bad-scenario");
  expect_input_error("simulate " + dir.string() + " -o " + (dir / "out").string(),
                     "is a directory, not a scenario file");
  // A valid YAML document of 5 MB (a long list under an unknown key).
  {
    std::ofstream big(dir / "big.yaml");
    big << kBar << "time: { end: 0.01 }\ndiagnose:\n";
    for (int k = 0; k < 400000; ++k) big << "  - 123456\n";
  }
  expect_input_error("simulate " + (dir / "big.yaml").string() + " -o " + (dir / "out").string(),
                     "is not a scenario file (at most 4 MB");
}

TEST(BadInputs, CommandLineRangeErrorsExitOne) {
  const fs::path dir = test::scratch("bad-cli");
  const std::string ok = scenario(dir, "ok", "time: { end: 0.01 }\n");
  expect_input_error("fit " + ok + " --max-evaluations 0", "must be a positive finite number");
  const auto unknown = run_kelvin("simulate " + ok + " --no-such-option");
  EXPECT_EQ(unknown.exit_code, 1) << unknown.out;
}

// Messages that once misled: each names the real problem at the key.
TEST(BadInputs, ScenarioValuesOutOfReachAreNamedForWhatTheyAre) {
  const fs::path dir = test::scratch("bad-values");
  const auto out = " -o " + (dir / "out").string();
  const std::string bar_E =
      std::string(kBar).replace(kBar.find("lambda: 1.0e5, mu: 1.0e5"), 24, "E: 1.0e308, nu: 0.3");
  test::write_text(dir / "E.yaml", bar_E + "time: { end: 0.01 }\n");
  expect_input_error("simulate " + (dir / "E.yaml").string() + out,
                     "lambda is beyond any material (at most 1e+20 Pa");
  const std::string bar_huge = std::string(kBar).replace(kBar.find("lambda: 1.0e5, mu: 1.0e5"), 24,
                                                         "lambda: 1.0e299, mu: 1.0e299");
  test::write_text(dir / "huge.yaml", bar_huge + "time: { end: 0.01 }\n");
  expect_input_error("simulate " + (dir / "huge.yaml").string() + out,
                     "huge.yaml:6:42: material.elastic.lambda: is beyond any material");
  expect_input_error(
      "simulate " + scenario(dir, "bigint", "time: { end: 0.01 }\nsolver: { max_steps: 1e30 }\n") +
          out,
      "solver.max_steps: 1e30 is too large (at most 9e15)");
  expect_input_error(
      "simulate " +
          scenario(dir, "merge", "time: { end: 0.01 }\nsolver:\n  <<: { rtol: 1.0e-4 }\n") + out,
      "merge.yaml:12:3: solver.<<: YAML merge keys are not supported");
  test::write_text(dir / "deep.yaml",
                   "name: " + std::string(100000, '[') + std::string(100000, ']') + "\n");
  expect_input_error("simulate " + (dir / "deep.yaml").string() + out,
                     "levels deep, the reader's limit");
  // A valid 1 m cylinder at 1 cm is 3.7 M tetrahedra (found by the scenario fuzzer:
  // seconds to build, more than a direct solve can hold).
  test::write_text(dir / "bigmesh.yaml",
                   bar_with_mesh("{ generate: cylinder, radius: 1.01, height: 0.2, "
                                 "element_size: 0.01 }") +
                       "time: { end: 0.01 }\n");
  expect_input_error("simulate " + (dir / "bigmesh.yaml").string() + out,
                     "mesh.element_size: 0.01 m would make 3.67e+06 tetrahedra, more than kelvin "
                     "meshes (at most 2e+06)");
  test::write_text(dir / "meshdir.yaml",
                   bar_with_mesh("{ file: " + dir.string() + " }") + "time: { end: 0.01 }\n");
  expect_input_error("simulate " + (dir / "meshdir.yaml").string() + out,
                     "mesh.file: '" + dir.string() + "' is a directory, not a file");
}

// A data file beyond what any simulation here can use is refused before it is read
// (a sparse file: no disk is spent), so memory stays bounded.
TEST(BadInputs, AnOversizedDataFileIsRefusedBeforeReading) {
  const fs::path dir = test::scratch("bad-size");
  const fs::path big = dir / "huge.msh";
  { std::ofstream(big).put('$'); }
  fs::resize_file(big, std::uintmax_t{600} << 20);
  test::write_text(dir / "big.yaml", bar_with_mesh("{ file: huge.msh }") + "time: { end: 0.01 }\n");
  expect_input_error(
      "simulate " + (dir / "big.yaml").string() + " -o " + (dir / "out").string(),
      "huge.msh: 600 MiB is more than kelvin reads as a mesh file (at most 512 MiB)");
  { std::ofstream(dir / "tracks.csv").put('t'); }
  fs::resize_file(dir / "tracks.csv", std::uintmax_t{600} << 20);
  expect_read_error([&] { read_marker_tracks((dir / "tracks.csv").string()); },
                    "600 MiB is more than kelvin reads as a CSV file");
  fs::remove(big);
  fs::remove(dir / "tracks.csv");
}

// scipy and ROS write quaternions x, y, z, w: a header that says so is read so.
TEST(BadInputs, AClampCsvHeaderSetsTheQuaternionOrder) {
  const fs::path dir = test::scratch("clamp-order");
  const double c = std::cos(0.3), s = std::sin(0.3);
  test::write_text(dir / "wxyz.csv", fmt::format("t,tx,ty,tz,qw,qx,qy,qz\n0,0,0,0,1,0,0,0\n"
                                                 "1,0.1,0,0,{},0,0,{}\n",
                                                 c, s));
  test::write_text(dir / "xyzw.csv", fmt::format("t,tx,ty,tz,qx,qy,qz,qw\n0,0,0,0,0,0,0,1\n"
                                                 "1,0.1,0,0,0,0,{},{}\n",
                                                 s, c));
  const ClampSamples a = read_clamp_csv((dir / "wxyz.csv").string());
  const ClampSamples b = read_clamp_csv((dir / "xyzw.csv").string());
  ASSERT_EQ(b.quaternion_wxyz.size(), 2u);
  EXPECT_LT((a.quaternion_wxyz[1] - b.quaternion_wxyz[1]).norm(), 1e-15);
  EXPECT_NEAR(b.quaternion_wxyz[1][0], c, 1e-15);  // w first inside kelvin

  test::write_text(dir / "typo.csv", "t,tx,ty,tz,qw,qx,qy,qq\n0,0,0,0,1,0,0,0\n1,0,0,0,1,0,0,0\n");
  expect_read_error([&] { read_clamp_csv((dir / "typo.csv").string()); },
                    "typo.csv:1: column 8 of the header is 'qq'");
  // A quaternion far from unit length is a wrong column, not a rotation to normalise.
  test::write_text(dir / "scaled.csv", "0,0,0,0,1,0,0,0\n1,0,0,0,2,0,0,0\n");
  expect_read_error([&] { read_clamp_csv((dir / "scaled.csv").string()); },
                    "scaled.csv:2: the quaternion");
}

// A body that blows up (near-zero stiffness under 10⁶ g) once sat inside one long
// step with SIGINT ignored; the interrupt now ends the step, and the run reports it.
TEST(BadInputs, AnInterruptStopsARunThatBlowsUpInsideAStep) {
  const fs::path dir = test::scratch("blow-up");
  test::write_text(dir / "blow.yaml", R"(
name: blow
mesh: { generate: box, lo: [0, 0, 0], hi: [0.1, 0.02, 0.02], element_size: 0.01 }
material:
  density: 1000
  elastic: { model: neo-hookean, lambda: 1.0e-3, mu: 1.0e-3 }
  viscous: { model: newtonian, nu: 1.0e-6 }
gravity: [0, 0, -1.0e6]
clamps:
  - { name: wall, select: { plane: { axis: x, at: 0 } } }
time: { end: 0.5 }
)");
  const Scenario s = load_scenario((dir / "blow.yaml").string());
  std::atomic<bool> interrupt{false};
  SimulationOptions o;
  o.outdir = (dir / "out").string();
  o.interrupt = &interrupt;
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    interrupt = true;
  });
  const SimulationResult r = run_simulation(s, o);
  stopper.join();
  // Uninterrupted, this run spends minutes in its first steps.
  EXPECT_TRUE(r.interrupted) << r.error;
  EXPECT_TRUE(r.error.empty()) << r.error;
  EXPECT_FALSE(r.completed);
  EXPECT_TRUE(fs::exists(dir / "out" / "summary.txt"));
}

// A plugin that crashes cannot be survived in kelvin's process; the crash is named
// (plugin, element), and the fit's state saved after every evaluation is kept.
TEST(BadInputs, APluginThatCrashesInsideAFitIsNamedAndTheBestSoFarIsKept) {
  const fs::path dir = test::scratch("plugin-crash");
  const auto bar = [&](double mu, double crash_above, const std::string& tail) {
    return fmt::format(R"(
name: crash
mesh: {{ generate: box, lo: [0, 0, 0], hi: [0.1, 0.02, 0.02], element_size: 0.01 }}
material:
  density: 1000
  elastic: {{ model: segfault-model, plugin: {}, mu: {}, crash_above: {}, crash_element: 7 }}
  viscous: {{ model: newtonian, nu: 5 }}
gravity: [0, 0, -9.81]
clamps:
  - {{ name: wall, select: {{ plane: {{ axis: x, at: 0 }} }} }}
markers:
  rest:
    - {{ name: tip, at: [0.1, 0.01, 0.01] }}
time: {{ end: 0.05, output_rate: 1000 }}
{})",
                       KELVIN_MISBEHAVING_PLUGIN, mu, crash_above, tail);
  };
  const std::string tracks = test::simulate_tracks(dir, "truth", bar(2e5, 1e19, ""));
  std::string fit_yaml =
      bar(1e5, 1.5e5, "fit: { parameters: [elastic.mu], max_evaluations: 20 }\n");
  fit_yaml.replace(fit_yaml.find("time:"), 0, "  observed: " + tracks + "\n");
  test::write_text(dir / "fit.yaml", fit_yaml);
  const std::string out = (dir / "out").string();
  const auto r = run_kelvin("fit " + (dir / "fit.yaml").string() + " -o " + out);
  EXPECT_EQ(r.exit_code, 128 + SIGSEGV) << r.out;
  EXPECT_NE(r.out.find("kelvin: crashed (segmentation fault) inside plugin material "
                       "'segfault-model' (" KELVIN_MISBEHAVING_PLUGIN ") at element 7"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("the best parameters so far are in " + out + "/fit-state.yaml"),
            std::string::npos)
      << r.out;
  // The evaluations before the crash (μ below the crash) are saved, and the command
  // the report prints writes the outputs from them without another trial.
  const std::string state = test::read_text(dir / "out" / "fit-state.yaml");
  EXPECT_EQ(state.find("evaluations: 0\n"), std::string::npos) << state;
  const std::string again = "--resume --max-evaluations 1";
  ASSERT_NE(r.out.find(again), std::string::npos) << r.out;
  const auto outputs =
      run_kelvin("fit " + (dir / "fit.yaml").string() + " -o " + out + " " + again);
  EXPECT_EQ(outputs.exit_code, 0) << outputs.out;
  EXPECT_TRUE(fs::exists(dir / "out" / "fitted.yaml"));
  EXPECT_TRUE(fs::exists(dir / "out" / "report.md"));
}

}  // namespace kelvin
