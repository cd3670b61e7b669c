#pragma once
// The bundled foam cylinder (yaml/examples/foam-cylinder.yaml) re-meshed at another
// element size, and fits to tracks simulated from it, shared by the benchmarks.
#include <string>
#include <vector>

#include "engine/csv.hpp"
#include "engine/markers.hpp"
#include "engine/mesh.hpp"
#include "engine/selection.hpp"
#include "yaml/scenario.hpp"

namespace kelvin::bench {

/// The example scenario re-meshed at element size h (clamps and markers re-resolved).
inline Scenario remeshed(const Scenario& base, double h) {
  Scenario s = base;
  s.mesh = generate_cylinder(0.01, 0.2, h, 2);
  for (auto& c : s.clamps) c.nodes = select_nodes(s.mesh, c.selection);
  std::vector<std::string> names;
  Eigen::Matrix3Xd rest(3, base.markers.embedded.size());
  for (size_t i = 0; i < base.markers.embedded.size(); ++i) {
    const auto& m = base.markers.embedded[i];
    names.push_back(m.name);
    rest.col(i).setZero();
    for (int a = 0; a < 4; ++a)
      rest.col(i) += m.weights[a] * base.mesh.nodes.col(base.mesh.tets(a, m.tet));
  }
  s.markers.embedded = embed_markers(s.mesh, names, rest, 1e-3);
  s.time.end = 1.0;
  s.time.vtu_rate = 0;
  return s;
}

/// `truth` observed: its marker tracks, simulated into dir/markers.csv, become the
/// scenario's observations.
inline Scenario observing(const Scenario& truth, const std::string& dir) {
  Scenario s = truth;
  s.path = dir + "/scenario.yaml";
  s.markers.observed_path = dir + "/markers.csv";
  s.markers.observed = read_marker_tracks(s.markers.observed_path);
  return s;
}

}  // namespace kelvin::bench
