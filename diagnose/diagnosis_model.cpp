#include "diagnose/diagnosis_model.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <set>
#include <utility>

#include "adjoint/result_exchange.hpp"
#include "base/error.hpp"
#include "base/spread_tasks.hpp"

namespace kelvin {

Model load_model(const std::string& source, const Scenario& nominal,
                 const std::vector<const Candidate*>& with, bool screening, const std::string& path,
                 int refit_form, Communicator& comm) {
  Model m;
  m.extended = write_extended_scenario(source, nominal, with, screening, path, refit_form);
  m.scenario = std::make_unique<Scenario>(load_scenario(path));
  m.problem = std::make_unique<FitProblem>(*m.scenario, m.scenario->fit.parameters, comm);
  // The stages read residuals per marker, frame and frequency band of captured motion.
  if (m.problem->num_static_terms() > 0)
    throw Error(fmt::format(
        "{}: fit.experiments: static measurements ('{}') are not diagnosed yet; diagnose the "
        "captured motions and fit the static ones jointly with kelvin fit",
        nominal.path, m.problem->static_term(0).name()));
  return m;
}

std::vector<int> entries_of(const Model& m, const std::vector<int>& specs) {
  std::vector<int> out;
  for (int k : specs) {
    const auto e = m.problem->map().entries_of_spec(k);
    out.insert(out.end(), e.begin(), e.end());
  }
  return out;
}

namespace {

/// A model of some of `with`'s candidates and where its entries sit in the joint one.
struct Part {
  Model model;
  std::vector<std::pair<int, int>> entries;  // (entry here, entry in the joint model)
};

Part load_part(const Model& joint, const std::string& source, const Scenario& nominal,
               const std::vector<const Candidate*>& with, const std::vector<int>& picked,
               int refit_form, const std::string& path) {
  std::vector<const Candidate*> list;
  int form = -1;
  for (int c : picked) {
    if (c == refit_form) form = static_cast<int>(list.size());
    list.push_back(with[c]);
  }
  // Each part runs on one rank (screening_system spreads them).
  Part part{load_model(source, nominal, list, true, path, form, serial_communicator()), {}};
  const ExtendedScenario& here = part.model.extended;
  const ExtendedScenario& there = joint.extended;
  const auto pair_up = [&](const std::vector<int>& a, const std::vector<int>& b) {
    if (a.size() != b.size())
      throw Error(fmt::format("internal: {} has {} entries where the joint screening model has {}",
                              path, a.size(), b.size()));
    for (std::size_t k = 0; k < a.size(); ++k) part.entries.emplace_back(a[k], b[k]);
  };
  std::vector<int> nominal_specs(static_cast<std::size_t>(there.nominal_specs));
  for (int k = 0; k < there.nominal_specs; ++k) nominal_specs[k] = k;
  pair_up(entries_of(part.model, nominal_specs), entries_of(joint, nominal_specs));
  for (std::size_t i = 0; i < picked.size(); ++i)
    pair_up(entries_of(part.model, here.candidate_specs[i]),
            entries_of(joint, there.candidate_specs[picked[i]]));
  return part;
}

}  // namespace

GaussNewtonSystem screening_system(const Model& m, const std::string& source,
                                   const Scenario& nominal,
                                   const std::vector<const Candidate*>& with, int refit_form,
                                   const Eigen::VectorXd& p, const std::filesystem::path& dir,
                                   const std::string& stem, const std::atomic<bool>* interrupt,
                                   Communicator& comm, BesideTask* beside, ScreeningCosts* costs) {
  if (m.extended.candidate_specs.size() != with.size())
    throw Error(fmt::format("internal: the screening model has {} candidates, the list {}",
                            m.extended.candidate_specs.size(), with.size()));
  const std::vector<int> model_entries = m.problem->map().model_entries();
  const std::set<int> moves(model_entries.begin(), model_entries.end());
  std::vector<int> base, own;  // candidates in the base run; those run one by one
  for (int c = 0; c < static_cast<int>(with.size()); ++c) {
    const std::vector<int> e = entries_of(m, m.extended.candidate_specs[c]);
    const bool moves_model =
        std::any_of(e.begin(), e.end(), [&](int j) { return moves.count(j) > 0; });
    (c == refit_form || !moves_model ? base : own).push_back(c);
  }

  const auto run = [&](Part& part, const std::vector<int>* sensitivity_entries) {
    Eigen::VectorXd q = part.model.problem->map().initial();
    for (const auto& [here, there] : part.entries) q[here] = p[there];
    return gauss_newton_system(*part.model.problem, q, interrupt, true, sensitivity_entries);
  };
  // Run 0 is the base; run k its k-th own candidate. Each returns its system with
  // the columns it fills and their index in the joint model, and the seconds it took.
  const auto key = [&](int k) {
    if (k == 0) return std::string("base");
    const Candidate& c = *with[own[k - 1]];
    return c.where.empty() ? c.id : c.id + "-" + c.where;
  };
  bool failed = false;  // a run failed on this rank: its later ones are not needed
  const auto part_run = [&](int k, const ProgressLine&) {
    const auto t0 = std::chrono::steady_clock::now();
    ByteWriter out;
    if (failed) {
      GaussNewtonSystem skipped;
      skipped.error = "not run";
      put(out, skipped);
      out.put(Eigen::VectorXd());
      out.put(0.0);
      return out.bytes();
    }
    std::vector<int> picked = base;
    if (k > 0) {
      picked = {own[k - 1]};
      if (refit_form >= 0) picked.insert(picked.begin(), refit_form);
    }
    Part part = load_part(m, source, nominal, with, picked, refit_form,
                          (dir / (stem + "-" + key(k) + ".yaml")).string());
    // A candidate's run integrates its own entries only: the base's columns are
    // known already.
    std::vector<int> mine;
    if (k > 0)
      mine = entries_of(part.model, part.model.extended.candidate_specs[picked.size() - 1]);
    GaussNewtonSystem gk = run(part, k > 0 ? &mine : nullptr);
    failed = !gk.ok;
    // Only the columns it fills, each with its index in the joint model.
    const std::set<int> own_entries(mine.begin(), mine.end());
    std::vector<std::pair<int, int>> kept;
    for (const auto& [here, there] : part.entries)
      if (gk.ok && (k == 0 || own_entries.count(here))) kept.emplace_back(here, there);
    Eigen::MatrixXd columns(gk.jacobian.rows(), static_cast<long>(kept.size()));
    Eigen::VectorXd column_of(static_cast<long>(kept.size()));
    for (std::size_t i = 0; i < kept.size(); ++i) {
      columns.col(static_cast<long>(i)) = gk.jacobian.col(kept[i].first);
      column_of[static_cast<long>(i)] = kept[i].second;
    }
    gk.jacobian = std::move(columns);
    put(out, gk);
    out.put(column_of);
    out.put(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    return out.bytes();
  };
  // Without known costs, `beside` first: it (often the longest) goes to rank 0, the
  // base run (the longest of the screening's) to the next.
  const int first = beside ? 1 : 0, n = first + 1 + static_cast<int>(own.size());
  std::vector<double> expected(static_cast<std::size_t>(n), 0.0);
  for (int k = first; k < n && costs && !beside; ++k)
    if (const auto at = costs->find(key(k - first)); at != costs->end()) expected[k] = at->second;
  std::vector<std::string> runs = spread_tasks(
      comm, n,
      [&](int k, const ProgressLine& line) {
        return k < first ? beside->run(k, line) : part_run(k - first, line);
      },
      beside ? beside->progress : nullptr, interrupt, task_ranks(expected, comm.size()));
  if (first) {
    beside->result = std::move(runs.front());
    runs.erase(runs.begin());
  }

  GaussNewtonSystem g;
  for (int k = 0; k < static_cast<int>(runs.size()); ++k) {
    GaussNewtonSystem gk;
    Eigen::VectorXd column_of;
    double seconds = 0;
    ByteReader in(runs[k]);
    get(in, gk);
    in.get(column_of);
    in.get(seconds);
    if (costs && seconds > 0) (*costs)[key(k)] = seconds;
    if (!gk.ok) {
      g.error =
          k == 0 ? gk.error : fmt::format("{} (screening {})", gk.error, with[own[k - 1]]->id);
      return g;
    }
    if (k == 0) {
      g.residual = gk.residual;
      g.samples = gk.samples;
      g.rtol = gk.rtol;
      g.jacobian = Eigen::MatrixXd::Zero(gk.residual.size(), m.problem->map().size());
    } else {
      // The same samples in the same order, or the columns would land on wrong rows.
      bool same = gk.samples.size() == g.samples.size();
      for (std::size_t i = 0; same && i < g.samples.size(); ++i)
        same = gk.samples[i].experiment == g.samples[i].experiment &&
               gk.samples[i].marker == g.samples[i].marker &&
               gk.samples[i].axis == g.samples[i].axis && gk.samples[i].t == g.samples[i].t;
      if (!same)
        throw Error(
            fmt::format("internal: screening {} sampled other residuals than the base model",
                        with[own[k - 1]]->id));
      g.rtol = std::max(g.rtol, gk.rtol);
    }
    for (long i = 0; i < column_of.size(); ++i)
      g.jacobian.col(static_cast<long>(column_of[i])) = gk.jacobian.col(i);
  }
  g.ok = true;
  return g;
}

}  // namespace kelvin
