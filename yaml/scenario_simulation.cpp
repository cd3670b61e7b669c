#include "yaml/scenario_simulation.hpp"

#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>

#include "base/error.hpp"
#include "engine/output.hpp"

namespace kelvin {
namespace {

MaterialTerm make_term(const MaterialTermSpec& spec, int num_tets) {
  std::shared_ptr<Material> model = create_material(spec.model, spec.plugin);
  const auto& params = model->params();
  Eigen::VectorXd q(params.size());
  for (size_t k = 0; k < params.size(); ++k) {
    auto it = spec.params.find(params[k].name);
    q[k] = it == spec.params.end() ? params[k].default_value : it->second;
  }
  Eigen::MatrixXd state;
  if (model->state_size() > 0) {
    const std::vector<double> s = spec.state.empty() ? model->default_state() : spec.state;
    state = Eigen::Map<const Eigen::VectorXd>(s.data(), s.size()).replicate(1, num_tets);
  }
  return {model, q.replicate(1, num_tets), state};
}

/// Output event times k/rate for k = 0.. up to `end` (with a tolerance so that
/// end itself is included when it is a multiple of the period).
std::vector<double> event_times(double rate, double end) {
  std::vector<double> t;
  if (rate <= 0) return t;
  // The loader bounds the frame count (time_span_problem); this guards the cast.
  const double frames = std::floor(end * rate * (1 + 1e-12) + 1e-9);
  if (!(frames < 1e9))
    throw Error(fmt::format("{:g} s at {:g} Hz are too many output frames", end, rate));
  const long count = static_cast<long>(frames);
  for (long k = 0; k <= count; ++k) t.push_back(std::min(end, k / rate));
  return t;
}

}  // namespace

std::unique_ptr<FemModel> build_model(const Scenario& s) {
  const int ne = s.mesh.num_tets();
  std::vector<MaterialTerm> terms;
  for (const auto& t : s.material.elastic) terms.push_back(make_term(t, ne));
  for (const auto& t : s.material.viscous) terms.push_back(make_term(t, ne));
  Eigen::VectorXd density = Eigen::VectorXd::Constant(ne, s.material.density);
  for (const auto& f : s.material.fields) {
    // The loader checks this for files; a Scenario assembled in code is not checked.
    if (f.values.size() != ne)
      throw Error(fmt::format("{}: material.fields: {} has {} values for {} elements",
                              s.material.fields_path, f.target, f.values.size(), ne));
    if (f.term >= static_cast<int>(terms.size()))
      throw Error(fmt::format("{}: material.fields: {} names a term the material lacks",
                              s.material.fields_path, f.target));
    if (f.term < 0)
      density = f.values;
    else
      terms[f.term].q.row(f.index) = f.values.transpose();
  }
  std::vector<ClampBinding> clamps;
  for (const auto& c : s.clamps)
    clamps.push_back({c.name, c.nodes, c.motion, c.compliance, c.damping_time, c.ramped});
  std::vector<NodeLoad> loads;
  for (const auto& l : s.loads) loads.push_back({l.name, l.nodes, l.force, l.mass});
  return std::make_unique<FemModel>(s.mesh, std::move(terms), std::move(density), s.gravity,
                                    std::move(clamps), s.solver.lumped_mass, std::move(loads));
}

IntegratorOptions integrator_options(const SolverSpec& solver) {
  IntegratorOptions o;
  o.rtol = solver.rtol;
  o.atol = solver.atol;
  o.velocity_atol_scale = solver.velocity_atol_scale;
  o.max_order = solver.max_order;
  o.max_steps = solver.max_steps;
  o.max_step = solver.max_step;
  o.initial_step = solver.initial_step;
  return o;
}

void initial_state(const Scenario& s, const FemModel& model, Eigen::VectorXd& x0,
                   Eigen::VectorXd& v0, StaticResult* static_result) {
  x0 = rigid_initial_guess(model, 0.0);
  v0.setZero(model.num_dofs());
  if (!s.static_initial) return;
  StaticResult r = solve_static(model, 0.0, x0);
  if (static_result) *static_result = r;
  if (!r.converged) throw Error(fmt::format("{}: initial: static: {}", s.path, r.message));
}

std::string SimulationResult::summary() const {
  std::string orders;
  for (int q = 1; q <= 5; ++q)
    if (stats.order_histogram[q]) orders += fmt::format(" {}:{}", q, stats.order_histogram[q]);
  const std::string statics =
      static_result.load_steps > 0
          ? fmt::format("static initial state: {} Newton iterations in {} load steps; ",
                        static_result.iterations, static_result.load_steps)
          : "";
  const std::string order_note = order ? order->summary() + "; " : "";
  return statics + order_note +
         fmt::format(
             "{} t = {:.6g} s in {:.3g} s wall: {} steps (mean order {:.2f};{}), {} residuals, "
             "{} Jacobians, {} factorizations, {} linear solves, {} error-test and {} convergence "
             "failures; {} marker frames, {} VTU frames",
             completed ? "completed" : (interrupted ? "interrupted at" : "FAILED at"), t_reached,
             wall_seconds, stats.steps, stats.mean_order(), orders, stats.residual_evals,
             stats.jacobian_evals, stats.linear_setups, stats.linear_solves,
             stats.error_test_failures, stats.convergence_failures, marker_frames, vtu_frames);
}

SimulationResult run_simulation(const Scenario& s, const SimulationOptions& opt) {
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  SimulationResult result;
  std::error_code ec;
  std::filesystem::create_directories(opt.outdir, ec);
  if (ec)
    throw Error(
        fmt::format("{}: cannot create the output directory ({})", opt.outdir, ec.message()));

  auto model = build_model(s);
  Eigen::VectorXd x0, v0;
  initial_state(s, *model, x0, v0, &result.static_result);

  const auto& markers = s.markers.embedded;
  std::vector<std::string> names;
  for (const auto& m : markers) names.push_back(m.name);
  MarkerCsvWriter marker_csv((std::filesystem::path(opt.outdir) / "markers.csv").string(), names);
  std::unique_ptr<VtuSeries> vtu;
  if (s.time.vtu_rate > 0)
    vtu = std::make_unique<VtuSeries>(opt.outdir, s.name.empty() ? "frame" : s.name, s.mesh);

  // Output events: time → (marker frame?, vtu frame?)
  std::map<double, std::pair<bool, bool>> events;
  if (!markers.empty())
    for (double t : event_times(s.time.output_rate, s.time.end)) events[t].first = true;
  for (double t : event_times(vtu ? s.time.vtu_rate : 0, s.time.end)) events[t].second = true;
  events[s.time.end];  // always integrate to the end

  IntegratorOptions iopt = integrator_options(s.solver);
  iopt.interrupt = opt.interrupt;
  if (iopt.max_order <= 0) {
    result.order = choose_max_order(*model, iopt, 0.0, s.time.end, x0, v0);
    iopt.max_order = result.order->max_order;
  }
  IdasIntegrator integrator(*model, iopt);
  integrator.initialize(0.0, x0, v0);

  Eigen::Matrix3Xd x, v;
  AssemblyOutput energy_out;
  AssemblyRequest energy_req;
  energy_req.force = false;
  energy_req.energy = true;
  auto last_flush = Clock::now();
  auto last_progress = Clock::now();
  auto write_frame = [&](double t, const Eigen::VectorXd& xf, const Eigen::VectorXd& vf,
                         std::pair<bool, bool> what) {
    model->expand(t, xf.data(), vf.data(), x, v);
    if (what.first) marker_csv.add_frame(t, marker_positions(s.mesh, markers, x));
    if (what.second) {
      model->assemble(x, v, energy_req, energy_out);
      vtu->write_frame(t, x, v, {{"strain_energy_density", energy_out.cell_energy}});
    }
  };

  bool ok = true;
  for (const auto& [t, what] : events) {
    if (opt.interrupt && opt.interrupt->load()) {
      result.interrupted = true;
      ok = false;
      break;
    }
    if (t > 0 && !integrator.advance_to(t, s.time.end)) {
      if (opt.interrupt && opt.interrupt->load())
        result.interrupted = true;
      else
        result.error = integrator.error();
      ok = false;
      break;
    }
    result.t_reached = t;
    write_frame(t, t > 0 ? integrator.positions() : x0, t > 0 ? integrator.velocities() : v0, what);
    if (Clock::now() - last_flush > std::chrono::seconds(2)) {
      if (!markers.empty()) marker_csv.flush();
      last_flush = Clock::now();
    }
    if (opt.progress && Clock::now() - last_progress > std::chrono::seconds(5)) {
      fmt::print(stderr, "  t = {:.4g} / {:.4g} s, {} steps\n", t, s.time.end,
                 integrator.stats().steps);
      last_progress = Clock::now();
    }
  }
  if (!markers.empty()) marker_csv.flush();
  result.completed = ok;
  result.stats = integrator.stats();
  result.marker_frames = marker_csv.frames();
  result.vtu_frames = vtu ? vtu->frames() : 0;
  result.wall_seconds = std::chrono::duration<double>(Clock::now() - start).count();
  write_file_atomic((std::filesystem::path(opt.outdir) / "summary.txt").string(),
                    result.summary() + (result.error.empty() ? "" : "\n" + result.error) + "\n");
  return result;
}

}  // namespace kelvin
