#include "parallel/mpi_communicator.hpp"

#include <mpi.h>

#include <climits>

#include "base/error.hpp"

namespace kelvin {

MpiRuntime::MpiRuntime(int& argc, char**& argv) {
  MPI_Init(&argc, &argv);
}

MpiRuntime::~MpiRuntime() {
  MPI_Finalize();
}

MpiCommunicator::MpiCommunicator(std::atomic<bool>* interrupted) : interrupted_(interrupted) {
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
}

std::vector<std::string> MpiCommunicator::all_gather(const std::string& mine) {
  // Sizes first, every rank: one rank's oversized share (−1) ends all of them alike.
  const int n = mine.size() > static_cast<size_t>(INT_MAX) ? -1 : static_cast<int>(mine.size());
  std::vector<int> sizes(size_), offsets(size_);
  MPI_Allgather(&n, 1, MPI_INT, sizes.data(), 1, MPI_INT, MPI_COMM_WORLD);
  long total = 0;
  for (int r = 0; r < size_; ++r) {
    if (sizes[r] < 0 || total > INT_MAX - sizes[r])
      throw Error("results shared between ranks exceed 2 GiB");
    offsets[r] = static_cast<int>(total);
    total += sizes[r];
  }
  std::string all(static_cast<size_t>(total), '\0');
  MPI_Allgatherv(mine.data(), n, MPI_CHAR, all.data(), sizes.data(), offsets.data(), MPI_CHAR,
                 MPI_COMM_WORLD);
  std::vector<std::string> out(size_);
  for (int r = 0; r < size_; ++r) out[r] = all.substr(offsets[r], sizes[r]);
  return out;
}

double MpiCommunicator::from_root(double value) {
  MPI_Bcast(&value, 1, MPI_DOUBLE, 0, MPI_COMM_WORLD);
  return value;
}

void MpiCommunicator::interrupt() {
  if (interrupted_) *interrupted_ = true;
}

}  // namespace kelvin
