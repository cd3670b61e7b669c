#pragma once
/// \file
/// The Communicator of `kelvin-mpi`: MPI_COMM_WORLD. Collectives fail loudly (MPI
/// aborts the job on an error, its default), so a rank never waits on a dead peer.
#include <atomic>

#include "base/communicator.hpp"

namespace kelvin {

/// MPI_Init on construction, MPI_Finalize on destruction: one per process.
class MpiRuntime {
 public:
  MpiRuntime(int& argc, char**& argv);
  ~MpiRuntime();
  MpiRuntime(const MpiRuntime&) = delete;
  MpiRuntime& operator=(const MpiRuntime&) = delete;
};

class MpiCommunicator : public Communicator {
 public:
  /// `interrupted` is set when another rank reports an interrupt (Communicator::interrupt).
  explicit MpiCommunicator(std::atomic<bool>* interrupted = nullptr);
  int rank() const override { return rank_; }
  int size() const override { return size_; }
  std::vector<std::string> all_gather(const std::string& mine) override;
  double from_root(double value) override;
  void interrupt() override;

 private:
  int rank_ = 0, size_ = 1;
  std::atomic<bool>* interrupted_;
};

}  // namespace kelvin
