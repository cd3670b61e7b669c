#pragma once
/// \file
/// The processes a run is spread over. A fit evaluates its experiments on the ranks
/// that own them and every rank goes on with every experiment's result, so all ranks
/// take the same path through the optimiser (each runs it; rank 0 writes the outputs).
/// The serial communicator is one rank; `kelvin-mpi` installs an MPI one
/// (parallel/mpi_communicator.hpp) as the world before any command runs.
#include <string>
#include <vector>

namespace kelvin {

class Communicator {
 public:
  virtual ~Communicator() = default;
  virtual int rank() const { return 0; }
  virtual int size() const { return 1; }
  bool root() const { return rank() == 0; }
  /// Collective: every rank's `mine`, in rank order, on every rank.
  virtual std::vector<std::string> all_gather(const std::string& mine) { return {mine}; }
  /// Collective: rank 0's `value` on every rank (a clock reading every rank must
  /// agree on, say).
  virtual double from_root(double value) { return value; }
  /// Another rank was interrupted (SIGINT/SIGTERM): this one stops as it would.
  virtual void interrupt() {}
};

/// One rank: collectives return what they are given.
inline Communicator& serial_communicator() {
  static Communicator serial;
  return serial;
}

/// The communicator of the process: serial unless a driver set another.
inline Communicator*& world_slot() {
  static Communicator* world = nullptr;
  return world;
}
inline Communicator& world() {
  return world_slot() ? *world_slot() : serial_communicator();
}
inline void set_world(Communicator* c) {
  world_slot() = c;
}

/// Collective: the message of the lowest rank whose `mine` is not empty, on every
/// rank ("" when none failed). An error one rank met alone (a file it cannot read)
/// ends every rank with one message.
inline std::string first_message(Communicator& comm, const std::string& mine) {
  if (comm.size() == 1) return mine;
  for (const std::string& m : comm.all_gather(mine))
    if (!m.empty()) return m;
  return "";
}

/// Collective: whether any rank was interrupted (`mine`: this one), raised on every
/// rank, so that all stop at the same point.
inline bool any_interrupted(Communicator& comm, bool mine) {
  if (comm.size() == 1) return mine;
  const bool any = !first_message(comm, mine ? "interrupted" : "").empty();
  if (any && !mine) comm.interrupt();
  return any;
}

}  // namespace kelvin
