#include "adjoint/parameter_map.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>

#include "base/error.hpp"

namespace kelvin {
namespace {

ParamSlot resolve_target(const std::string& target, const Scenario& s, int line) {
  if (const int axis = body_force_axis(target); axis >= 0) return {-1, 0, -1, axis};
  if (const std::string name = clamp_of_compliance_target(target); !name.empty())
    for (int c = 0; c < static_cast<int>(s.clamps.size()); ++c)
      if (s.clamps[c].name == name && s.clamps[c].compliance > 0) return {-1, 0, c};
  const auto quantities = material_quantities(s.material);
  if (const MaterialQuantity* q = find_quantity(quantities, target)) return {q->term, q->index};
  throw Error(fmt::format("{}:{}: fit.parameters: '{}' is not a parameter of this model", s.path,
                          line, target));
}

/// The model's value of a slot in element e.
double slot_value(const FemModel& model, const ParamSlot& slot, int e) {
  if (slot.is_clamp()) return model.clamps()[slot.clamp].compliance;
  if (slot.is_force())
    return slot.index < model.body_force().knots()
               ? model.body_force().value(slot.force, slot.index, e)
               : 0.0;
  return slot.is_density() ? model.density()[e] : model.terms()[slot.term].q(slot.index, e);
}

Eigen::Vector3d centroid(const Mesh& mesh, int e) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int a = 0; a < 4; ++a) c += mesh.nodes.col(mesh.tets(a, e));
  return c / 4;
}

/// Legendre polynomials P₀ … P_degree at s ∈ [−1, 1] (Bonnet's recurrence).
Eigen::VectorXd legendre(double s, int degree) {
  Eigen::VectorXd P(degree + 1);
  P[0] = 1;
  if (degree >= 1) P[1] = s;
  for (int k = 1; k < degree; ++k) P[k + 1] = ((2 * k + 1) * s * P[k] - k * P[k - 1]) / (k + 1);
  return P;
}

/// The slots a spec acts on: its quantity, or for elastic.moduli every parameter in
/// Pa of every elastic term.
std::vector<std::pair<ParamSlot, std::string>> spec_slots(const FitParameterSpec& spec,
                                                          const Scenario& s) {
  if (spec.target != kElasticModuli) {
    const ParamSlot slot = resolve_target(spec.target, s, spec.line);
    return {{slot, spec.target}};
  }
  std::vector<std::pair<ParamSlot, std::string>> out;
  for (const MaterialQuantity& q : material_quantities(s.material))
    if (q.term >= 0 && q.term < static_cast<int>(s.material.elastic.size()) && q.info.unit == "Pa")
      out.push_back({{q.term, q.index}, q.name});
  if (out.empty())
    throw Error(
        fmt::format("{}:{}: fit.parameters: {} scales the elastic parameters in Pa, and "
                    "this material has none",
                    s.path, spec.line, kElasticModuli));
  return out;
}

/// The typical size of a linear parameter (FitParameterSpec::scale): the given one,
/// else its start's size, else, for one that starts at 0, the smallest non-zero
/// quantity of the scenario in the same unit (a stiffening c₂ takes μ's), else a
/// millimetre or millisecond for observations and 1 otherwise.
double typical_scale(const FitParameterSpec& spec, const Scenario& s,
                     const Eigen::VectorXd& start) {
  if (spec.scale > 0) return spec.scale;
  if (start.size() && start.cwiseAbs().maxCoeff() > 0) return start.cwiseAbs().maxCoeff();
  if (spec.target.rfind("markers.", 0) == 0) return 1e-3;
  if (body_force_axis(spec.target) >= 0) return s.gravity.norm() > 0 ? s.gravity.norm() : 1.0;
  const auto quantities = material_quantities(s.material);
  const MaterialQuantity* self = find_quantity(quantities, spec.target);
  double smallest = HUGE_VAL;
  if (self)
    for (const auto& q : quantities)
      if (&q != self && q.info.unit == self->info.unit && q.value != 0)
        smallest = std::min(smallest, std::abs(q.value));
  return std::isfinite(smallest) ? smallest : 1.0;
}

/// The observation block of a `markers.…` target (its θ entries and labels).
ObservationBlock observation_block(const FitParameterSpec& spec, const Scenario& s,
                                   const std::vector<std::string>& observed) {
  const int nm = static_cast<int>(observed.size());
  ObservationBlock o;
  o.target = spec.target;
  o.lower = spec.lower;
  o.upper = spec.upper;
  if (spec.target == kClockOffset) {
    o.theta = 0;
    o.labels = {spec.target};
  } else if (spec.target == kRegistration) {
    o.theta = 1 + 3 * nm;
    o.labels = {"markers.registration.rx", "markers.registration.ry", "markers.registration.rz",
                "markers.registration.tx", "markers.registration.ty", "markers.registration.tz"};
  } else {
    const std::string name = marker_of_offset_target(spec.target);
    const auto it = std::find(observed.begin(), observed.end(), name);
    if (name.empty() || it == observed.end())
      throw Error(fmt::format("{}:{}: fit.parameters: '{}' names no observed marker", s.path,
                              spec.line, spec.target));
    o.theta = 1 + 3 * static_cast<int>(it - observed.begin());
    for (const char* c : {"x", "y", "z"}) o.labels.push_back(spec.target + "." + c);
  }
  o.count = static_cast<int>(o.labels.size());
  o.initial = Eigen::VectorXd::Constant(o.count, spec.initial.value_or(0.0));
  o.scale = typical_scale(spec, s, o.initial);
  return o;
}

}  // namespace

ParameterMap::ParameterMap(const std::vector<FitParameterSpec>& specs, const Scenario& s,
                           const FemModel& model, const std::vector<std::string>& observed) {
  const Mesh& mesh = model.mesh();
  const int ne = mesh.num_tets();
  using Scope = FitParameterSpec::Scope;
  for (const auto& spec : specs) {
    spec_begin_.push_back(size_);
    if (spec.target.rfind("markers.", 0) == 0) {
      ObservationBlock o = observation_block(spec, s, observed);
      o.offset = size_;
      for (int j = 0; j < o.count; ++j)
        block_of_.push_back(-1 - static_cast<int>(observation_blocks_.size()));
      size_ += o.count;
      observation_blocks_.push_back(std::move(o));
      continue;
    }
    ParameterBlock b;
    b.log = spec.log;
    b.lower = spec.lower;
    b.upper = spec.upper;
    b.offset = size_;
    b.entry.assign(ne, -1);
    std::vector<std::string> suffix;
    switch (spec.scope) {
      case Scope::Global:
        std::fill(b.entry.begin(), b.entry.end(), 0);
        suffix = {""};
        break;
      case Scope::PerRegion: {
        std::map<int, int> index;
        for (int e = 0; e < ne; ++e) index.emplace(mesh.region[e], 0);
        for (auto& [label, i] : index) {
          i = static_cast<int>(suffix.size());
          suffix.push_back(fmt::format("[region {}]", label));
        }
        for (int e = 0; e < ne; ++e) b.entry[e] = index[mesh.region[e]];
        break;
      }
      case Scope::PerElement:
        for (int e = 0; e < ne; ++e) {
          b.entry[e] = e;
          suffix.push_back(fmt::format("[{}]", e));
        }
        b.per_element = true;
        break;
      case Scope::Boxes: {
        // Box k takes the elements whose centroid it holds first; the rest share
        // one more entry. Boxes that hold no element get no entry.
        const int nb = static_cast<int>(spec.boxes.size());
        std::vector<int> raw(ne, nb);
        for (int e = 0; e < ne; ++e) {
          const Eigen::Vector3d c = centroid(mesh, e);
          for (int k = 0; k < nb; ++k)
            if ((c.array() >= spec.boxes[k].first.array()).all() &&
                (c.array() <= spec.boxes[k].second.array()).all()) {
              raw[e] = k;
              break;
            }
        }
        std::map<int, int> used;
        for (int e = 0; e < ne; ++e) used.emplace(raw[e], 0);
        for (auto& [k, i] : used) {
          i = static_cast<int>(suffix.size());
          suffix.push_back(k < nb ? fmt::format("[box {}]", k) : "[outside boxes]");
        }
        for (int e = 0; e < ne; ++e) b.entry[e] = used[raw[e]];
        break;
      }
      case Scope::Legendre: {
        const int axis = spec.legendre_axis, degree = spec.legendre_degree;
        const int from = spec.legendre_from;
        const double lo = mesh.nodes.row(axis).minCoeff(), hi = mesh.nodes.row(axis).maxCoeff();
        b.basis.resize(ne, degree + 1 - from);
        for (int e = 0; e < ne; ++e) {
          b.entry[e] = 0;
          const double x = hi > lo ? 2 * (centroid(mesh, e)[axis] - lo) / (hi - lo) - 1 : 0.0;
          b.basis.row(e) = legendre(x, degree).tail(degree + 1 - from).transpose();
        }
        for (int k = from; k <= degree; ++k)
          suffix.push_back(fmt::format("[P{} along {}]", k, "xyz"[axis]));
        break;
      }
    }
    // A body force has one block of the scope's entries per knot in time.
    const bool force = body_force_axis(spec.target) >= 0;
    const int copies = force ? spec.knots : 1;
    if (force && copies < 1)
      throw Error(fmt::format("{}:{}: fit.parameters: {} needs knots (≥ 1)", s.path, spec.line,
                              spec.target));
    for (const auto& other : specs)
      if (force && body_force_axis(other.target) >= 0 && other.knots != copies)
        throw Error(
            fmt::format("{}:{}: fit.parameters: every body-force target needs the same "
                        "knots ({} has {}, {} has {})",
                        s.path, spec.line, spec.target, copies, other.target, other.knots));
    b.penalty = spec.penalty;
    b.knots = force ? copies : 0;
    b.force_end = force ? s.time.end : 0;
    auto knot_suffix = [&](int k) {
      return force ? fmt::format("[t {:.4g} s]", s.time.end * (k + 1) / (copies + 1))
                   : std::string();
    };
    const ParameterBlock scoped = b;
    for (int knot = 0; knot < copies; ++knot) {
      b = scoped;
      b.offset = size_;
      b.count = static_cast<int>(suffix.size());
      for (int j = 0; j < b.count; ++j)
        b.labels.push_back(spec.target + suffix[j] + knot_suffix(knot));
      // A multiplier of regions (elastic.moduli): the indicator basis, in log space.
      const bool multiplier = spec.scope == Scope::Legendre || spec.target == kElasticModuli;
      if (multiplier && !b.is_multiplier()) {
        b.basis = Eigen::MatrixXd::Zero(ne, b.count);
        for (int e = 0; e < ne; ++e)
          if (b.entry[e] >= 0) b.basis(e, b.entry[e]) = 1;
      }
      b.initial.resize(b.count);
      if (multiplier) {
        b.initial.setConstant(spec.initial.value_or(spec.scope == Scope::Legendre ? 0.0 : 1.0));
      } else {
        // Start from the given value, else from the model's current value in the entry's elements.
        b.slot = resolve_target(spec.target, s, spec.line);
        if (b.slot.is_force()) b.slot.index = knot;
        for (int e = ne - 1; e >= 0; --e)
          if (b.entry[e] >= 0) b.initial[b.entry[e]] = slot_value(model, b.slot, e);
        if (spec.initial) b.initial.setConstant(*spec.initial);
        if (!b.log) b.scale = typical_scale(spec, s, b.initial);
      }
      for (int j = 0; j < b.count; ++j) {
        if (b.log && !(b.initial[j] > 0))
          throw Error(
              fmt::format("{}:{}: fit.parameters: {} starts at {:g}, but a log-transformed "
                          "parameter must be positive",
                          s.path, spec.line, b.labels[j], b.initial[j]));
        if (b.initial[j] < b.lower || b.initial[j] > b.upper)
          throw Error(fmt::format("{}:{}: fit.parameters: {} starts at {:g}, outside [{:g}, {:g}]",
                                  s.path, spec.line, b.labels[j], b.initial[j], b.lower, b.upper));
      }
      for (int j = 0; j < b.count; ++j) block_of_.push_back(static_cast<int>(blocks_.size()));
      size_ += b.count;
      // One block per slot; those after the first share its entries of p.
      const auto slots = spec_slots(spec, s);
      for (size_t k = 0; k < slots.size(); ++k) {
        ParameterBlock sb = b;
        sb.slot = slots[k].first;
        if (sb.slot.is_force()) sb.slot.index = knot;
        sb.target = slots[k].second;
        sb.shares_entries = k > 0;
        if (sb.is_multiplier()) {
          sb.nominal.resize(ne);
          for (int e = 0; e < ne; ++e) sb.nominal[e] = slot_value(model, sb.slot, e);
        }
        blocks_.push_back(std::move(sb));
      }
    }
  }
  // Which blocks act on the same slot: the last value block sets it, multipliers scale it.
  const int nb = static_cast<int>(blocks_.size());
  value_block_.assign(nb, -1);
  multipliers_.assign(nb, {});
  auto same = [](const ParamSlot& a, const ParamSlot& b) {
    return a.term == b.term && a.clamp == b.clamp && a.force == b.force &&
           ((!a.is_material() && !a.is_force()) || a.index == b.index);
  };
  for (int k = 0; k < nb; ++k)
    for (int o = 0; o < nb; ++o) {
      if (!same(blocks_[k].slot, blocks_[o].slot)) continue;
      if (blocks_[o].is_multiplier()) {
        multipliers_[k].push_back(o);
      } else {
        if (value_block_[k] >= 0 && value_block_[k] != o)
          throw Error(
              fmt::format("{}: fit.parameters: {} is fitted twice (as {} and {}); one "
                          "value per quantity (multipliers such as {} may add to it)",
                          s.path, blocks_[o].target, blocks_[value_block_[k]].labels[0],
                          blocks_[o].labels[0], kElasticModuli));
        value_block_[k] = o;
      }
    }
}

std::vector<ParamSlot> ParameterMap::slots() const {
  std::vector<ParamSlot> out;
  for (const auto& b : blocks_) out.push_back(b.slot);
  return out;
}

std::vector<int> ParameterMap::entries_of_spec(int k) const {
  const int end = k + 1 < static_cast<int>(spec_begin_.size()) ? spec_begin_[k + 1] : size_;
  std::vector<int> out;
  for (int j = spec_begin_[k]; j < end; ++j) out.push_back(j);
  return out;
}

std::vector<int> ParameterMap::model_entries() const {
  std::vector<int> out;
  for (int j = 0; j < size_; ++j)
    if (block_of_[j] >= 0) out.push_back(j);
  return out;
}

std::string ParameterMap::label(int j) const {
  if (block_of_[j] < 0) {
    const auto& o = observation_blocks_[-1 - block_of_[j]];
    return o.labels[j - o.offset];
  }
  const auto& b = blocks_[block_of_[j]];
  return b.labels[j - b.offset];
}

Eigen::VectorXd ParameterMap::initial() const {
  Eigen::VectorXd p(size_);
  for (const auto& b : blocks_)
    for (int j = 0; j < b.count; ++j)
      p[b.offset + j] = b.log ? std::log(b.initial[j]) : b.initial[j];
  for (const auto& o : observation_blocks_) p.segment(o.offset, o.count) = o.initial;
  return p;
}

Eigen::VectorXd ParameterMap::lower() const {
  Eigen::VectorXd p(size_);
  for (const auto& b : blocks_)
    p.segment(b.offset, b.count)
        .setConstant(b.log ? (b.lower > 0 ? std::log(b.lower) : -HUGE_VAL) : b.lower);
  for (const auto& o : observation_blocks_) p.segment(o.offset, o.count).setConstant(o.lower);
  return p;
}

Eigen::VectorXd ParameterMap::upper() const {
  Eigen::VectorXd p(size_);
  for (const auto& b : blocks_)
    p.segment(b.offset, b.count)
        .setConstant(b.log ? (b.upper < 1e300 ? std::log(b.upper) : HUGE_VAL) : b.upper);
  for (const auto& o : observation_blocks_) p.segment(o.offset, o.count).setConstant(o.upper);
  return p;
}

Eigen::VectorXd ParameterMap::units() const {
  Eigen::VectorXd u = Eigen::VectorXd::Ones(size_);
  for (const auto& b : blocks_)
    if (!b.log && !b.is_multiplier()) u.segment(b.offset, b.count).setConstant(b.scale);
  for (const auto& o : observation_blocks_) u.segment(o.offset, o.count).setConstant(o.scale);
  return u;
}

double ParameterMap::value(const Eigen::VectorXd& p, int j) const {
  return is_log(j) ? std::exp(p[j]) : p[j];
}

double ParameterMap::derivative(const Eigen::VectorXd& p, int j) const {
  return is_log(j) ? std::exp(p[j]) : 1.0;
}

Eigen::VectorXd ParameterMap::observation_vector(const Eigen::VectorXd& p, int theta_size) const {
  Eigen::VectorXd theta = Eigen::VectorXd::Zero(theta_size);
  for (const auto& o : observation_blocks_)
    theta.segment(o.theta, o.count) = p.segment(o.offset, o.count);
  return theta;
}

void ParameterMap::add_observation_gradient(const Eigen::VectorXd& dphi_dtheta,
                                            Eigen::VectorXd& gradient) const {
  for (const auto& o : observation_blocks_)
    gradient.segment(o.offset, o.count) += dphi_dtheta.segment(o.theta, o.count);
}

double ParameterMap::multiplier(const Eigen::VectorXd& p, int s, int e) const {
  double m = 1;
  for (int o : multipliers_[s]) {
    const ParameterBlock& b = blocks_[o];
    if (b.entry[e] >= 0) m *= std::exp(b.basis.row(e).dot(p.segment(b.offset, b.count)));
  }
  return m;
}

double ParameterMap::element_value(const Eigen::VectorXd& p, int s, int e) const {
  const int v = value_block_[s];
  const ParameterBlock& b = blocks_[s];
  double base = b.is_multiplier() ? b.nominal[e] : 0.0;
  if (v >= 0 && blocks_[v].entry[e] >= 0) base = value(p, blocks_[v].offset + blocks_[v].entry[e]);
  return base * multiplier(p, s, e);
}

void ParameterMap::apply(const Eigen::VectorXd& p, FemModel& model) const {
  if (p.size() != size_) throw Error("parameter vector has the wrong size");
  Eigen::VectorXd density = model.density();
  bool density_changed = false;
  for (const auto& b : blocks_)
    if (b.slot.is_force())
      model.body_force().configure(0, b.force_end, b.knots, model.mesh().num_tets());
  for (int s = 0; s < static_cast<int>(blocks_.size()); ++s) {
    const auto& b = blocks_[s];
    for (int e = 0; e < static_cast<int>(b.entry.size()); ++e) {
      if (b.entry[e] < 0) continue;
      const double q = element_value(p, s, e);
      if (b.slot.is_force()) {
        model.body_force().value(b.slot.force, b.slot.index, e) = q;
      } else if (b.slot.is_clamp()) {
        model.set_clamp_compliance(b.slot.clamp, q);  // one value: every entry holds it
      } else if (b.slot.is_density()) {
        density[e] = q;
        density_changed = true;
      } else {
        model.terms()[b.slot.term].q(b.slot.index, e) = q;
      }
    }
  }
  if (density_changed) model.set_density(std::move(density));
  model.update_rest_tangents();
}

int ParameterMap::index(int s, int e) const {
  const auto& b = blocks_[s];
  return b.entry[e] < 0 || b.is_multiplier() ? -1 : b.offset + b.entry[e];
}

double ParameterMap::prior_penalty(const Eigen::VectorXd& p, Eigen::VectorXd* g) const {
  double sum = 0;
  for (const auto& b : blocks_) {
    if (b.penalty <= 0 || b.shares_entries) continue;
    const Eigen::VectorXd z = p.segment(b.offset, b.count) / b.scale;
    sum += b.penalty * z.squaredNorm();
    if (g) g->segment(b.offset, b.count) += 2 * b.penalty * z / b.scale;
  }
  return sum;
}

bool ParameterMap::has_body_force() const {
  return std::any_of(blocks_.begin(), blocks_.end(),
                     [](const ParameterBlock& b) { return b.slot.is_force(); });
}

std::vector<std::pair<int, int>> ParameterMap::neighbour_pairs(const Mesh& mesh) const {
  // Elements sharing a face: sort each tet's faces by node ids and match them.
  std::map<std::array<int, 3>, int> first;
  std::vector<std::pair<int, int>> element_pairs;
  for (int e = 0; e < mesh.num_tets(); ++e)
    for (int f = 0; f < 4; ++f) {
      std::array<int, 3> face;
      for (int a = 0, k = 0; a < 4; ++a)
        if (a != f) face[k++] = mesh.tets(a, e);
      std::sort(face.begin(), face.end());
      const auto [it, inserted] = first.emplace(face, e);
      if (!inserted) element_pairs.emplace_back(it->second, e);
    }
  std::vector<std::pair<int, int>> out;
  for (int s = 0; s < static_cast<int>(blocks_.size()); ++s) {
    const ParameterBlock& b = blocks_[s];
    if (!b.per_element || b.shares_entries) continue;
    for (const auto& [e1, e2] : element_pairs)
      out.emplace_back(b.offset + b.entry[e1], b.offset + b.entry[e2]);
  }
  return out;
}

}  // namespace kelvin
