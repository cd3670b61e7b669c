#include "adjoint/experiment.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "adjoint/experiment_run.hpp"
#include "base/error.hpp"
#include "yaml/scenario_simulation.hpp"

namespace kelvin {

GradientMethod parse_gradient_method(const std::string& name) {
  if (name == "adjoint") return GradientMethod::kAdjoint;
  if (name == "forward") return GradientMethod::kForward;
  if (name == "none") return GradientMethod::kNone;
  throw Error(fmt::format("unknown gradient method '{}' (adjoint, forward or none)", name));
}

const char* to_string(GradientMethod m) {
  switch (m) {
    case GradientMethod::kAdjoint:
      return "adjoint";
    case GradientMethod::kForward:
      return "forward";
    default:
      return "none";
  }
}

namespace {
MarkerObjective make_objective(const Scenario& s, const ObjectiveSpec& spec) {
  const bool targets = !spec.targets.empty();
  if (s.markers.observed_path.empty() && !targets)
    throw Error(fmt::format(
        "{}: markers.observed: the scenario has no captured tracks to fit (nor shape targets, "
        "fit.objective.targets)",
        s.path));
  try {
    return MarkerObjective(s.markers.embedded, s.markers.observed, spec, s.time.end, targets);
  } catch (const Error& e) {
    throw Error(fmt::format("{}: {}", s.path, e.what()));
  }
}
}  // namespace

Experiment::Experiment(const Scenario& scenario, const ObjectiveSpec& objective)
    : scenario_(scenario),
      model_(build_model(scenario)),
      objective_(make_objective(scenario, objective)) {
  // A run shortened after loading (gradcheck --end) would leave a target unseen:
  // Φ without it, and a gradient check that passes on nothing.
  for (const ShapeTargetSpec& t : objective.targets) {
    if (t.time > scenario.time.end)
      throw Error(fmt::format(
          "{}:{}: fit.objective.targets: '{}' at t = {:g} s lies after the end of the run "
          "(t = {:g} s)",
          scenario.path, t.line, t.name, t.time, scenario.time.end));
    targets_.emplace_back(t, scenario.mesh);
  }
}

double Experiment::objective_weight() const {
  double w = 0;
  for (int i = 0; i < objective_.num_markers(); ++i) w += objective_.weighted_observed_time(i);
  for (const ShapeTarget& t : targets_) w += t.weight() * t.coordinates();
  return w;
}

double Experiment::rms(const Eigen::VectorXd& phi_per_marker,
                       const Eigen::VectorXd& phi_targets) const {
  return std::sqrt(2 * (phi_per_marker.sum() + phi_targets.sum()) / objective_weight());
}

void Experiment::apply(const ParameterMap& map, const Eigen::VectorXd& p) {
  map.apply(p, *model_);
  objective_.set_observation_vector(
      map.observation_vector(p, objective_.num_observation_parameters()));
}

ExperimentResult Experiment::evaluate(const ParameterMap& map, const Eigen::VectorXd& p,
                                      const GradientOptions& options, EvaluationPlan& plan) {
  const auto start = std::chrono::steady_clock::now();
  ExperimentResult result;
  apply(map, p);
  try {
    ExperimentRun run(*this, plan, map, p, options);
    switch (options.method) {
      case GradientMethod::kNone:
        evaluate_objective(run, result);
        break;
      case GradientMethod::kForward:
        evaluate_forward_sensitivities(run, result);
        break;
      case GradientMethod::kAdjoint:
        evaluate_adjoint(run, result);
        break;
    }
  } catch (const IoError&) {
    throw;
  } catch (const Error& e) {
    // Inadmissible trial parameters (e.g. no static equilibrium) fail this evaluation only.
    result.ok = false;
    result.error = e.what();
  }
  if (result.phi_per_marker.size() || result.phi_targets.size()) {
    result.phi = result.phi_per_marker.sum() + result.phi_targets.sum();
    result.rms = rms(result.phi_per_marker, result.phi_targets);
  }
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

ExperimentRun::ExperimentRun(Experiment& e, EvaluationPlan& pl, const ParameterMap& m,
                             const Eigen::VectorXd& params, const GradientOptions& o)
    : ex(e),
      plan(pl),
      model(e.model()),
      objective(e.objective()),
      map(m),
      p(params),
      opt(o),
      iopt(integrator_options(e.scenario().solver)),
      deriv(e.model(), m.slots()),
      dae(e.model()),
      n(e.model().num_dofs()),
      t_end(e.scenario().time.end) {
  iopt.rtol *= o.tolerance_scale;
  iopt.atol *= o.tolerance_scale;
  if (o.method != GradientMethod::kNone && !m.observation_blocks().empty())
    observation_count = objective.num_observation_parameters();
  const int ne = model.mesh().num_tets(), ns = static_cast<int>(deriv.slots().size());
  dependency_ptr.assign(static_cast<std::size_t>(ns) * ne + 1, 0);
  for (int s = 0; s < ns; ++s)
    for (int e = 0; e < ne; ++e) {
      map.for_each_dependency(p, s, e, [&](int j, double dq) { dependencies.emplace_back(j, dq); });
      dependency_ptr[static_cast<std::size_t>(s) * ne + e + 1] =
          static_cast<int>(dependencies.size());
    }
  initial_state(ex.scenario(), model, x0, v0);
  if (model.num_internal() > 0) {
    z0.resize(model.num_internal());
    Eigen::Matrix3Xd xs, vs;
    model.expand(t0, x0.data(), nullptr, xs, vs);
    model.relaxed_internal(xs, z0.data());
  }
  if (iopt.max_order <= 0)
    iopt.max_order = plan.order_cap(model, iopt, t_end, x0, v0, o.tolerance_scale);
}

namespace {
/// Times closer than this fraction of the run are one time.
constexpr double kSameTime = 1e-9;
}  // namespace

std::vector<double> ExperimentRun::fixed_times() const {
  const double eps = kSameTime * (t_end - t0);
  std::vector<double> b{t0, t_end};
  for (const ShapeTarget& target : ex.targets())
    if (target.time() > t0 + eps && target.time() < t_end - eps) b.push_back(target.time());
  std::sort(b.begin(), b.end());
  b.erase(std::unique(b.begin(), b.end(), [eps](double a, double c) { return c - a <= eps; }),
          b.end());
  return b;
}

std::vector<double> ExperimentRun::boundaries() const {
  std::vector<double> b = fixed_times();
  if (const double length = plan.segment_length(opt.segment); length > 0) {
    const std::vector<double> fixed = b;
    const int segments = std::max(1, static_cast<int>(std::ceil((t_end - t0) / length - 1e-9)));
    for (int k = 1; k < segments; ++k) {
      const double t = t0 + k * length;
      // A sliver of a segment next to a target time would only cost a restart.
      if (std::none_of(fixed.begin(), fixed.end(),
                       [&](double f) { return std::abs(f - t) < 0.01 * length; }))
        b.push_back(t);
    }
    std::sort(b.begin(), b.end());
  }
  return b;
}

template <class Visit>
void ExperimentRun::visit_targets_at(double t, const Eigen::VectorXd& x_free, Visit visit) {
  Eigen::Matrix3Xd xs, vs;
  bool expanded = false;
  const auto& targets = ex.targets();
  for (size_t k = 0; k < targets.size(); ++k) {
    if (std::abs(targets[k].time() - t) > kSameTime * (t_end - t0)) continue;
    if (!expanded) model.expand(t, x_free.data(), nullptr, xs, vs);
    expanded = true;
    visit(static_cast<Eigen::Index>(k), targets[k], xs);
  }
}

void ExperimentRun::add_targets(double t, const Eigen::VectorXd& x_free, ExperimentResult& result) {
  const auto count = static_cast<Eigen::Index>(ex.targets().size());
  if (count == 0) return;
  if (result.phi_targets.size() != count) result.phi_targets.setZero(count);
  visit_targets_at(t, x_free,
                   [&](Eigen::Index k, const ShapeTarget& target, const Eigen::Matrix3Xd& xs) {
                     result.phi_targets[k] += target.value(xs);
                   });
}

void ExperimentRun::add_target_gradient(double t, const Eigen::VectorXd& x_free, double* gradient) {
  visit_targets_at(t, x_free,
                   [&](Eigen::Index, const ShapeTarget& target, const Eigen::Matrix3Xd& xs) {
                     target.add_gradient(model, xs, gradient);
                   });
}

long ExperimentRun::checkpoint_budget() const {
  return opt.checkpoint_steps > 0 ? opt.checkpoint_steps : default_checkpoint_steps(dae.size());
}

bool ExperimentRun::integrate_segments(
    const std::vector<double>& T, int count, ExperimentResult& result,
    const std::function<void(int, IdasIntegrator&)>& segment_done) {
  Eigen::VectorXd xk = x0, vk = v0, zk = z0;
  double first_step = 0;
  add_targets(T[0], x0, result);
  for (int k = 0; k < count; ++k) {
    auto integ = start(T[k], xk, vk, zk, first_step);
    const bool ok = advance(*integ, T[k + 1], result);
    result.forward_stats.steps += integ->stats().steps;
    // After a failure the quadrature cannot be read at the last output time (IDAS
    // stepped past it): reading it threw, and the trial's error became "could not
    // interpolate the quadratures" instead of what stopped it.
    if (!ok) return false;
    add_quadratures(*integ, result);
    add_targets(T[k + 1], integ->positions(), result);
    xk = integ->positions();
    vk = integ->velocities();
    zk = integ->internal();
    first_step = integ->restart_step();
    if (segment_done) segment_done(k, *integ);
  }
  return true;
}

void ExperimentRun::expand(double t, const double* y, const double* yp) {
  t_state = t;
  model.expand(t, y, y + n, x, v);
  model.expand_acceleration(t, yp + n, a);
  z = Eigen::Map<const Eigen::VectorXd>(y + 2 * n, model.num_internal());
}

std::unique_ptr<IdasIntegrator> ExperimentRun::start(double t, const Eigen::VectorXd& x_free,
                                                     const Eigen::VectorXd& v_free,
                                                     const Eigen::VectorXd& z_internal,
                                                     double first_step) {
  IntegratorOptions o = iopt;
  if (first_step > 0)
    o.initial_step = o.max_step > 0 ? std::min(first_step, o.max_step) : first_step;
  auto integ = std::make_unique<IdasIntegrator>(model, o);
  integ->initialize(t, x_free, v_free, z_internal);
  // Φ's integrand has kinks at every capture frame (linear tracks) and jumps where
  // a marker drops out; across them BDF quadrature without error control loses
  // about 1e-6 of Φ, which finite differences and Taylor tests see. With error
  // control IDAS resolves them; the absolute tolerance is the misfit error of a
  // 1 mm residual whose marker is off by the position tolerance.
  const double atol = 1e-3 * iopt.atol * (t_end - t0);
  const int nm = objective.num_markers();
  if (nm + observation_count == 0) return integ;  // shape targets alone
  integ->add_quadrature(
      nm + observation_count,
      [this, nm](double tt, const double* y, const double*, double* g) {
        model.expand(tt, y, nullptr, x, v);
        objective.integrand(tt, model, x, g);
        if (observation_count > 0) objective.observation_gradient(tt, model, x, g + nm);
        return true;
      },
      true, atol);
  return integ;
}

void ExperimentRun::add_quadratures(const IdasIntegrator& integ, ExperimentResult& result) const {
  const int nm = objective.num_markers();
  if (result.phi_per_marker.size() != nm) result.phi_per_marker.setZero(nm);
  if (nm + observation_count == 0) return;
  const Eigen::VectorXd q = integ.quadrature();
  result.phi_per_marker += q.head(nm);
  if (observation_count == 0) return;
  if (result.dphi_dtheta.size() != observation_count) result.dphi_dtheta.setZero(observation_count);
  result.dphi_dtheta += q.tail(observation_count);
}

bool ExperimentRun::advance(IdasIntegrator& integ, double t1, ExperimentResult& result,
                            std::optional<double> t_stop) {
  // Chunks only so that an interrupt is noticed; the stop time stays fixed, so the
  // steps do not depend on the chunking.
  const double chunk = std::max((t_end - t0) / 100, 1e-3);
  // The interrupt is checked after each chunk, never before the first: IDAS's
  // adjoint memory is allocated by the first IDASolveF, and IDAFree crashes on an
  // adjoint memory that never integrated.
  for (double t = integ.time(); t < t1;) {
    t = std::min(t1, t + chunk);
    // The step limit as it stands at the chunk's end, enforced step by step: a
    // trial can spend thousands of steps within one chunk (one took 12k steps in
    // 0.02 s of the bench bar, near a collapse).
    result.t_furthest = std::max(result.t_furthest, t);
    const double progress = (result.t_furthest - t0) / (t_end - t0);
    const long limit = static_cast<long>(
        std::ceil(static_cast<double>(opt.max_steps) * std::max(progress, opt.step_pace_floor)));
    const long budget = opt.max_steps > 0 ? std::max(1L, limit - result.forward_stats.steps) : 0;
    if (!integ.advance_to(t, t_stop.value_or(t1), budget)) {
      result.error = integ.error();
      if (result.error.empty()) {  // the budget ran out
        const std::string paced =
            limit < opt.max_steps ? fmt::format(" by then, {} over the whole run", opt.max_steps)
                                  : "";
        result.error = fmt::format(
            "abandoned at t = {:.6g} s after more than {} integrator steps (the limit for this "
            "trial{})",
            integ.solver_time(), limit, paced);
      }
      result.t_reached = integ.solver_time();
      return false;
    }
    if (t < t1 && opt.interrupt && opt.interrupt->load()) {
      result.error = fmt::format("interrupted at t = {:.6g} s", integ.time());
      result.t_reached = integ.time();
      return false;
    }
  }
  result.t_reached = t1;
  return true;
}

bool ExperimentRun::param_vectors(Eigen::MatrixXd& B) {
  B.setZero(n + model.num_internal(), map.size());
  const auto& elements = model.elements();
  const std::size_t ne = elements.size();
  const auto& blocks = model.internal_blocks();
  return deriv.for_each(
      t_state, x, v, a,
      [&](int e, int s, const Vec12& dR) {
        const std::size_t k0 = dependency_ptr[s * ne + e], k1 = dependency_ptr[s * ne + e + 1];
        for (std::size_t k = k0; k < k1; ++k) {
          const auto [j, dq] = dependencies[k];
          for (int i = 0; i < 12; ++i)
            if (const int d = model.dof(elements[e].nodes[i / 3], i % 3); d >= 0)
              B(d, j) += dq * dR[i];
        }
      },
      nullptr, z.size() ? z.data() : nullptr,
      [&](int b, int s, const Eigen::VectorXd& dF) {
        const int e = blocks[b].element;
        const std::size_t k0 = dependency_ptr[s * ne + e], k1 = dependency_ptr[s * ne + e + 1];
        for (std::size_t k = k0; k < k1; ++k) {
          const auto [j, dq] = dependencies[k];
          B.col(j).segment(n + blocks[b].offset, blocks[b].size) += dq * dF;
        }
      });
}

bool ExperimentRun::contract(const double* lambda, double scale, double* out,
                             const ElementTangents* cached, const double* lambda_z) {
  const auto& elements = model.elements();
  const std::size_t ne = elements.size();
  const auto& blocks = model.internal_blocks();
  const auto add = [&](int e, int s, double sum) {
    const std::size_t k0 = dependency_ptr[s * ne + e], k1 = dependency_ptr[s * ne + e + 1];
    for (std::size_t k = k0; k < k1; ++k)
      out[dependencies[k].first] += scale * sum * dependencies[k].second;
  };
  const bool internal = lambda_z && z.size();
  return deriv.for_each(
      t_state, x, v, a,
      [&](int e, int s, const Vec12& dR) {
        double sum = 0;
        for (int k = 0; k < 12; ++k)
          if (const int d = model.dof(elements[e].nodes[k / 3], k % 3); d >= 0)
            sum += lambda[d] * dR[k];
        add(e, s, sum);
      },
      cached, z.size() ? z.data() : nullptr,
      [&](int b, int s, const Eigen::VectorXd& dF) {
        if (!internal) return;
        const InternalBlock& blk = blocks[b];
        add(blk.element, s,
            Eigen::Map<const Eigen::VectorXd>(lambda_z + blk.offset, blk.size).dot(dF));
      });
}

void ExperimentRun::factor_static_stiffness() {
  Eigen::Matrix3Xd xs, vs;
  model.expand(t0, x0.data(), v0.data(), xs, vs);
  AssemblyOutput out;
  if (!model.assemble(xs, vs, {true, true, false, false}, out))
    throw Error(
        fmt::format("the static initial state has an inverted element {}", out.failed_element));
  K0.emplace();
  K0->compute(to_sparse_matrix(model.pattern(), out.K));
  if (K0->info() != Eigen::Success)
    throw Error("the stiffness at the static initial state is singular");
  // ∂R/∂q at the static state: no velocity, no acceleration, internal variables relaxed.
  t_state = t0;
  x = xs;
  v.setZero(3, xs.cols());
  a.setZero(3, xs.cols());
  z.resize(0);
}

void ExperimentRun::set_adjoint_scale(const ExperimentResult& result) {
  const double duration = t_end - t0;
  misfit_rms = std::max(ex.rms(result.phi_per_marker, result.phi_targets), iopt.atol);
  const EvaluationPlan::AdjointPeaks& peaks = plan.adjoint_peaks();
  if (peaks.x > 0 && peaks.v > 0) {
    lambda_x_ref = peaks.x * misfit_rms;
    lambda_v_ref = peaks.v * misfit_rms;
    return;
  }
  double mass = 0;
  for (int e = 0; e < model.mesh().num_tets(); ++e)
    mass += model.density()[e] * model.elements()[e].volume;
  const double node_mass = mass / model.mesh().num_nodes();
  // A target adds a jump of w_k · its residual to λx.
  double jumps = 0;
  for (Eigen::Index k = 0; k < result.phi_targets.size(); ++k)
    jumps += ex.targets()[k].weight() * ex.targets()[k].rms(result.phi_targets[k]);
  lambda_x_ref = misfit_rms * duration + jumps;
  lambda_v_ref = lambda_x_ref * duration / std::max(node_mass, 1e-300);
}

bool ExperimentRun::plan_segments(ExperimentResult& plain) {
  plain.phi_per_marker.setZero(objective.num_markers());
  const std::vector<double> T = fixed_times();
  if (!integrate_segments(T, static_cast<int>(T.size()) - 1, plain)) return false;
  plan.plan_segments(plain.forward_stats.steps, checkpoint_budget(), t_end - t0,
                     opt.tolerance_scale);
  plain.ok = true;
  return true;
}

void evaluate_objective(ExperimentRun& run, ExperimentResult& result) {
  if (run.planning()) {
    // A failed planning run, or a plan of one segment: that run is the answer.
    ExperimentResult plain;
    if (!run.plan_segments(plain) || run.boundaries() == run.fixed_times()) {
      result = plain;
      return;
    }
  }
  // Segmented like the adjoint, so that Φ belongs to the same trajectory.
  const std::vector<double> T = run.boundaries();
  result.segments = static_cast<int>(T.size()) - 1;
  result.phi_per_marker.setZero(run.objective.num_markers());
  if (!run.integrate_segments(T, result.segments, result)) return;
  result.ok = true;
}

}  // namespace kelvin
