#pragma once
/// \file
/// Independent tasks spread over the ranks of a communicator: each task runs on one
/// rank alone (whatever it simulates, on a serial communicator), and every rank
/// receives every task's packed result, in task order. The ranks then go on together
/// with the numbers a serial run computes task after task.
#include <algorithm>
#include <atomic>
#include <exception>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include "base/bytes.hpp"
#include "base/communicator.hpp"
#include "base/error.hpp"

namespace kelvin {

using ProgressLine = std::function<void(const std::string&)>;
/// Task k: its result packed (ByteWriter::bytes()), its progress lines through `say`.
using SpreadTask = std::function<std::string(int k, const ProgressLine& say)>;

/// The rank of each task: costliest first to the least loaded rank (the lowest on a
/// tie), when every cost is known (> 0) — costs every rank holds alike, so that all
/// compute the same assignment — else task k on rank k mod size.
inline std::vector<int> task_ranks(const std::vector<double>& costs, int size) {
  std::vector<int> rank(costs.size());
  const bool known = std::all_of(costs.begin(), costs.end(), [](double c) { return c > 0; });
  if (!known) {
    for (std::size_t k = 0; k < costs.size(); ++k) rank[k] = static_cast<int>(k) % size;
    return rank;
  }
  std::vector<std::size_t> order(costs.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return costs[a] > costs[b]; });
  std::vector<double> load(static_cast<std::size_t>(size), 0.0);
  for (std::size_t k : order) {
    const auto least = std::min_element(load.begin(), load.end()) - load.begin();
    rank[k] = static_cast<int>(least);
    load[static_cast<std::size_t>(least)] += costs[k];
  }
  return rank;
}

/// Collective: task k runs on rank ranks[k] (k mod size when `ranks` is not one per
/// task). A task's progress lines are printed as they come on rank 0 and, for the
/// tasks of other ranks, by rank 0 in task order once they are gathered. The
/// first task (in task order) that threw has its message rethrown on every rank —
/// a kelvin::Error as one, anything else as std::runtime_error — and an interrupt
/// seen on any rank is raised on all (Communicator::interrupt), so no rank waits for
/// one that stopped and all take the same path afterwards.
inline std::vector<std::string> spread_tasks(Communicator& comm, int n, const SpreadTask& task,
                                             const ProgressLine& progress,
                                             const std::atomic<bool>* interrupt,
                                             std::vector<int> ranks = {}) {
  const int size = comm.size();
  if (static_cast<int>(ranks.size()) != n) ranks = task_ranks(std::vector<double>(n, 0.0), size);
  ByteWriter mine;
  bool failed = false;  // a rank's tasks after one that threw are not run, as in serial
  for (int k = 0; k < n; ++k) {
    if (ranks[k] != comm.rank()) continue;
    std::vector<std::string> lines;
    const ProgressLine say = [&](const std::string& line) {
      if (!comm.root())
        lines.push_back(line);
      else if (progress)
        progress(line);
    };
    std::string result, error;
    bool input_error = false;
    try {
      if (!failed) result = task(k, say);
    } catch (const Error& e) {
      error = e.what();
      input_error = true;
    } catch (const std::exception& e) {
      error = e.what();
    }
    failed = failed || !error.empty();
    mine.put(error);
    mine.put(input_error);
    mine.put(result);
    mine.put(static_cast<long>(lines.size()));
    for (const std::string& line : lines) mine.put(line);
  }
  mine.put(interrupt && interrupt->load());
  const std::vector<std::string> shares = comm.all_gather(mine.bytes());
  std::vector<ByteReader> from;
  from.reserve(shares.size());
  for (const std::string& s : shares) from.emplace_back(s);
  std::vector<std::string> results(static_cast<std::size_t>(n));
  std::string error;
  bool input_error = false;
  for (int k = 0; k < n; ++k) {
    ByteReader& in = from[static_cast<std::size_t>(ranks[k])];
    std::string message;
    bool input = false;
    long count = 0;
    in.get(message);
    in.get(input);
    in.get(results[static_cast<std::size_t>(k)]);
    in.get(count);
    for (long i = 0; i < count; ++i) {
      std::string line;
      in.get(line);
      if (comm.root() && progress) progress(line);  // (none from rank 0's own tasks)
    }
    if (error.empty() && !message.empty()) {
      error = message;
      input_error = input;
    }
  }
  bool stopped = false;
  for (ByteReader& in : from) {
    bool s = false;
    in.get(s);
    stopped = stopped || s;
    if (!in.done()) throw Error("internal: a rank's task results were not read to their end");
  }
  if (stopped) comm.interrupt();
  if (!error.empty()) {
    if (input_error) throw Error(error);
    throw std::runtime_error(error);
  }
  return results;
}

}  // namespace kelvin
