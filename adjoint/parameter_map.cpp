#include "adjoint/parameter_map.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>

#include "engine/error.hpp"

namespace kelvin {
namespace {

ParamSlot resolve_target(const std::string& target, const FemModel& model, const Scenario& s,
                         int line) {
  if (target == "density") return {};
  const auto dot = target.find('.');
  const std::string part = target.substr(0, dot),
                    name = dot == std::string::npos ? "" : target.substr(dot + 1);
  const int term = part == "elastic" ? 0 : (part == "viscous" && s.material.viscous ? 1 : -1);
  if (term >= 0) {
    const auto& params = model.terms()[term].model->params();
    for (int k = 0; k < static_cast<int>(params.size()); ++k)
      if (params[k].name == name) return {term, k};
  }
  throw Error(fmt::format("{}:{}: fit.parameters: '{}' is not a parameter of this model", s.path,
                          line, target));
}

Eigen::Vector3d centroid(const Mesh& mesh, int e) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int a = 0; a < 4; ++a) c += mesh.nodes.col(mesh.tets(a, e));
  return c / 4;
}

}  // namespace

ParameterMap::ParameterMap(const std::vector<FitParameterSpec>& specs, const Scenario& s,
                           const FemModel& model) {
  const Mesh& mesh = model.mesh();
  const int ne = mesh.num_tets();
  for (const auto& spec : specs) {
    ParameterBlock b;
    b.target = spec.target;
    b.slot = resolve_target(spec.target, model, s, spec.line);
    b.log = spec.log;
    b.lower = spec.lower;
    b.upper = spec.upper;
    b.offset = size_;
    b.entry.assign(ne, -1);
    std::vector<std::string> suffix;
    using Scope = FitParameterSpec::Scope;
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
    }
    b.count = static_cast<int>(suffix.size());
    b.initial.resize(b.count);
    for (int j = 0; j < b.count; ++j) b.labels.push_back(spec.target + suffix[j]);
    // Start from the given value, else from the model's current value in the entry's elements.
    for (int e = ne - 1; e >= 0; --e)
      if (b.entry[e] >= 0)
        b.initial[b.entry[e]] = b.slot.is_density() ? model.density()[e]
                                                    : model.terms()[b.slot.term].q(b.slot.index, e);
    if (spec.initial) b.initial.setConstant(*spec.initial);
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
    blocks_.push_back(std::move(b));
  }
}

std::vector<ParamSlot> ParameterMap::slots() const {
  std::vector<ParamSlot> out;
  for (const auto& b : blocks_) out.push_back(b.slot);
  return out;
}

std::string ParameterMap::label(int j) const {
  const auto& b = blocks_[block_of_[j]];
  return b.labels[j - b.offset];
}

Eigen::VectorXd ParameterMap::initial() const {
  Eigen::VectorXd p(size_);
  for (const auto& b : blocks_)
    for (int j = 0; j < b.count; ++j)
      p[b.offset + j] = b.log ? std::log(b.initial[j]) : b.initial[j];
  return p;
}

Eigen::VectorXd ParameterMap::lower() const {
  Eigen::VectorXd p(size_);
  for (const auto& b : blocks_)
    p.segment(b.offset, b.count)
        .setConstant(b.log ? (b.lower > 0 ? std::log(b.lower) : -HUGE_VAL) : b.lower);
  return p;
}

Eigen::VectorXd ParameterMap::upper() const {
  Eigen::VectorXd p(size_);
  for (const auto& b : blocks_)
    p.segment(b.offset, b.count)
        .setConstant(b.log ? (b.upper < 1e300 ? std::log(b.upper) : HUGE_VAL) : b.upper);
  return p;
}

double ParameterMap::value(const Eigen::VectorXd& p, int j) const {
  return blocks_[block_of_[j]].log ? std::exp(p[j]) : p[j];
}

double ParameterMap::derivative(const Eigen::VectorXd& p, int j) const {
  return blocks_[block_of_[j]].log ? std::exp(p[j]) : 1.0;
}

void ParameterMap::apply(const Eigen::VectorXd& p, FemModel& model) const {
  if (p.size() != size_) throw Error("parameter vector has the wrong size");
  Eigen::VectorXd density = model.density();
  bool density_changed = false;
  for (const auto& b : blocks_)
    for (int e = 0; e < static_cast<int>(b.entry.size()); ++e) {
      if (b.entry[e] < 0) continue;
      const double q = value(p, b.offset + b.entry[e]);
      if (b.slot.is_density()) {
        density[e] = q;
        density_changed = true;
      } else {
        model.terms()[b.slot.term].q(b.slot.index, e) = q;
      }
    }
  if (density_changed) model.set_density(std::move(density));
  model.update_rest_tangents();
}

int ParameterMap::index(int s, int e) const {
  const auto& b = blocks_[s];
  return b.entry[e] < 0 ? -1 : b.offset + b.entry[e];
}

Eigen::VectorXd ParameterMap::pull_back(const Eigen::VectorXd& p,
                                        const Eigen::MatrixXd& dphi_dq) const {
  Eigen::VectorXd g = Eigen::VectorXd::Zero(size_);
  for (int s = 0; s < static_cast<int>(blocks_.size()); ++s)
    for (int e = 0; e < static_cast<int>(dphi_dq.cols()); ++e)
      if (const int j = index(s, e); j >= 0) g[j] += dphi_dq(s, e);
  for (int j = 0; j < size_; ++j) g[j] *= derivative(p, j);
  return g;
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
    if (!blocks_[s].per_element) continue;
    for (const auto& [e1, e2] : element_pairs) out.emplace_back(index(s, e1), index(s, e2));
  }
  return out;
}

}  // namespace kelvin
