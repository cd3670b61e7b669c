#pragma once
/// \file
/// Independent tasks spread over the ranks of a communicator: task k runs on rank
/// k mod size alone (whatever it simulates, on a serial communicator), and every rank
/// receives every task's packed result, in task order. The ranks then go on together
/// with the numbers a serial run computes task after task.
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

/// Collective. A task's progress lines are printed as they come on rank 0 and, for
/// the tasks of other ranks, by rank 0 in task order once they are gathered. The
/// first task (in task order) that threw has its message rethrown on every rank —
/// a kelvin::Error as one, anything else as std::runtime_error — and an interrupt
/// seen on any rank is raised on all (Communicator::interrupt), so no rank waits for
/// one that stopped and all take the same path afterwards.
inline std::vector<std::string> spread_tasks(Communicator& comm, int n, const SpreadTask& task,
                                             const ProgressLine& progress,
                                             const std::atomic<bool>* interrupt) {
  const int size = comm.size();
  ByteWriter mine;
  bool failed = false;  // a rank's tasks after one that threw are not run, as in serial
  for (int k = comm.rank(); k < n; k += size) {
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
    ByteReader& in = from[static_cast<std::size_t>(k % size)];
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
      if (comm.root() && progress) progress(line);
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
