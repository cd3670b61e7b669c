// Cost of the constitutive models: one stress+tangent evaluation per built-in model,
// and a full stiffness assembly of the 8k-tet foam cylinder with the built-in
// neo-Hookean model against the same model loaded as a plugin. Medians of repeats;
// asserts nothing about time.
//
//   build/bin/bench_materials [--repeat N]
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <random>

#include "engine/fem_model.hpp"
#include "engine/mesh.hpp"
#include "materials/material.hpp"

using namespace kelvin;
using Clock = std::chrono::steady_clock;

namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

template <class F>
double timed(F f) {
  const auto start = Clock::now();
  f();
  return std::chrono::duration<double>(Clock::now() - start).count();
}

std::vector<double> defaults(const Material& m) {
  std::vector<double> q;
  for (const auto& p : m.params()) q.push_back(p.default_value);
  return q;
}

double assembly_seconds(const Mesh& mesh, std::shared_ptr<const Material> model, int repeat) {
  const int ne = mesh.num_tets();
  const std::vector<double> q = defaults(*model);
  MaterialTerm term{
      model, Eigen::Map<const Eigen::VectorXd>(q.data(), q.size()).replicate(1, ne), {}};
  FemModel fem(mesh, {term}, Eigen::VectorXd::Constant(ne, 60), Eigen::Vector3d::Zero(), {}, true);
  Eigen::Matrix3Xd x = mesh.nodes, v = Eigen::Matrix3Xd::Zero(3, mesh.num_nodes());
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0, 1e-4);
  for (int a = 0; a < x.cols(); ++a) x.col(a) += Eigen::Vector3d(n(rng), n(rng), n(rng));
  AssemblyRequest req;
  req.stiffness = true;
  AssemblyOutput out;
  std::vector<double> t;
  for (int r = 0; r < repeat; ++r) t.push_back(timed([&] { fem.assemble(x, v, req, out); }));
  return median(t);
}

}  // namespace

int main(int argc, char** argv) {
  int repeat = 7;
  for (int i = 1; i < argc; ++i)
    if (!std::strcmp(argv[i], "--repeat") && i + 1 < argc) repeat = std::atoi(argv[++i]);

  fmt::print("stress + dP/dF (+ dP/dFdot for viscous models) per evaluation, median of {}\n",
             repeat);
  fmt::print("{:<20} {:>12}\n", "model", "ns / eval");
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.2, 0.2);
  const int evals = 20000;
  std::vector<Mat3> F(evals), Fdot(evals);
  for (int k = 0; k < evals; ++k) {
    F[k] = Mat3::Identity();
    for (int i = 0; i < 9; ++i) F[k](i % 3, i / 3) += u(rng), Fdot[k](i % 3, i / 3) = 5 * u(rng);
  }
  for (const auto& name : builtin_material_names()) {
    auto m = create_builtin_material(name);
    const std::vector<double> q = defaults(*m);
    std::vector<double> state = m->default_state();
    const unsigned request = kStress | kTangent | (m->is_viscous() ? kRateTangent : 0u);
    MaterialResponse r;
    MaterialPoint p;
    p.q = q.data();
    p.state = state.empty() ? nullptr : state.data();
    std::vector<double> t;
    for (int rep = 0; rep < repeat; ++rep)
      t.push_back(timed([&] {
        for (int k = 0; k < evals; ++k) {
          p.F = F[k];
          p.Fdot = Fdot[k];
          m->evaluate(p, request, r);
        }
      }));
    fmt::print("{:<20} {:>12.0f}\n", name, 1e9 * median(t) / evals);
  }

  const Mesh mesh = generate_cylinder(0.01, 0.2, 0.004, 2);
  const double builtin = assembly_seconds(mesh, create_material("neo-hookean", ""), repeat);
  const double plugin =
      assembly_seconds(mesh, create_material("neo-hookean", KELVIN_NH_PLUGIN), repeat);
  fmt::print("\nstiffness + force assembly, foam cylinder {} tets, neo-Hookean, median of {}\n",
             mesh.num_tets(), repeat);
  fmt::print(
      "built-in {:.2f} ms, plugin {:.2f} ms: the plugin boundary costs {:+.1f}% of assembly\n",
      1e3 * builtin, 1e3 * plugin, 100 * (plugin / builtin - 1));
  return 0;
}
