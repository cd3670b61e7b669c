#pragma once
// A scenario file, parsed and validated. Everything here is resolved: the mesh is
// loaded, clamp selections are node lists, CSV files are read, markers embedded.
// The engine builds a model from this without knowing about YAML.
#include <Eigen/Core>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "engine/markers.hpp"
#include "engine/mesh.hpp"
#include "engine/rigid_motion.hpp"
#include "engine/selection.hpp"

namespace kelvin {

/// One constitutive term (`elastic:` or `viscous:`): model name and parameter values.
struct MaterialTermSpec {
  std::string model;                     // e.g. "neo-hookean", "newtonian", "power-law"
  std::map<std::string, double> params;  // every parameter of the model, defaults filled in
  std::string plugin;                    // path of a plugin library ("" for built-ins)
  std::vector<double> state;             // per-element fixed state; empty = model's default
};

struct MaterialSpec {
  double density = 0;  // kg/m³
  MaterialTermSpec elastic;
  std::optional<MaterialTermSpec> viscous;
};

struct ClampSpec {
  std::string name;
  NodeSelection selection;
  std::vector<int> nodes;               // resolved, non-empty
  std::shared_ptr<RigidMotion> motion;  // FixedMotion when none is given
};

struct MarkersSpec {
  std::vector<MarkerEmbedding> embedded;  // empty when the scenario has no markers
  std::string observed_path;              // optional captured tracks ("" if none)
};

struct TimeSpec {
  double end = 1.0;          // s
  double output_rate = 100;  // frames per second for marker CSV
  double vtu_rate = 0;       // frames per second for VTU output; 0 = none
};

struct SolverSpec {
  double rtol = 1e-6;
  double atol = 1e-9;  // positions (m); velocities use atol × velocity_atol_scale
  double velocity_atol_scale = 100;
  int max_order = 5;
  long max_steps = 1000000;  // over the whole run
  double max_step = 0;       // 0 = unlimited
  double initial_step = 0;   // 0 = IDAS default
  bool lumped_mass = true;
};

struct Scenario {
  std::string name;
  std::string path;  // the scenario file, for messages
  Mesh mesh;
  MaterialSpec material;
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();
  bool static_initial = false;  // initial: static (equilibrium at t=0) or rest
  std::vector<ClampSpec> clamps;
  MarkersSpec markers;
  TimeSpec time;
  SolverSpec solver;
};

/// Parses and validates a scenario. Throws kelvin::Error whose message begins
/// "file:line:col: key.path: " and says why the value is refused.
Scenario load_scenario(const std::string& path);

}  // namespace kelvin
