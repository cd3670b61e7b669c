#pragma once
/// \file
/// Values packed into a byte string and read back in the same order: results that
/// one rank computes and every rank needs (base/communicator.hpp). Same machine
/// type on every rank; no versioning, nothing written to disk.
#include <Eigen/Core>
#include <array>
#include <climits>
#include <cstring>
#include <string>
#include <type_traits>

#include "base/error.hpp"

namespace kelvin {

class ByteWriter {
 public:
  template <class T>
  requires std::is_trivially_copyable_v<T>
  void put(const T& v) { bytes_.append(reinterpret_cast<const char*>(&v), sizeof(T)); }
  void put(const std::string& s) {
    put(static_cast<long>(s.size()));
    bytes_.append(s);
  }
  void put(const Eigen::VectorXd& v) {
    put(static_cast<long>(v.size()));
    bytes_.append(reinterpret_cast<const char*>(v.data()), sizeof(double) * v.size());
  }
  void put(const Eigen::MatrixXd& m) {
    put(static_cast<long>(m.rows()));
    put(static_cast<long>(m.cols()));
    bytes_.append(reinterpret_cast<const char*>(m.data()), sizeof(double) * m.size());
  }
  /// One call for packing and unpacking alike (fields walked in one list).
  template <class T>
  void operator()(const T& v) {
    put(v);
  }
  const std::string& bytes() const { return bytes_; }

 private:
  std::string bytes_;
};

class ByteReader {
 public:
  explicit ByteReader(const std::string& bytes) : bytes_(bytes) {}
  template <class T>
  requires std::is_trivially_copyable_v<T>
  void get(T& v) { take(&v, sizeof(T)); }
  void get(std::string& s) {
    long n = 0;
    get(n);
    check(n);
    s.assign(bytes_, at_, static_cast<size_t>(n));
    at_ += static_cast<size_t>(n);
  }
  void get(Eigen::VectorXd& v) {
    long n = 0;
    get(n);
    check(n * static_cast<long>(sizeof(double)));
    v.resize(n);
    take(v.data(), sizeof(double) * n);
  }
  void get(Eigen::MatrixXd& m) {
    long r = 0, c = 0;
    get(r);
    get(c);
    check(r < 0 || c < 0 || (c > 0 && r > LONG_MAX / 8 / c)
              ? -1
              : r * c * static_cast<long>(sizeof(double)));
    m.resize(r, c);
    take(m.data(), sizeof(double) * r * c);
  }
  template <class T>
  void operator()(T& v) {
    get(v);
  }
  bool done() const { return at_ == bytes_.size(); }
  /// A list's length n read back, checked against what is left to read.
  std::size_t items(long n) const {
    check(n);
    return static_cast<std::size_t>(n);
  }

 private:
  void check(long n) const {
    if (n < 0 || at_ + static_cast<size_t>(n) > bytes_.size())
      throw Error("a message between ranks is truncated (ranks built from different sources?)");
  }
  void take(void* out, size_t n) {
    check(static_cast<long>(n));
    std::memcpy(out, bytes_.data() + at_, n);
    at_ += n;
  }
  const std::string& bytes_;
  size_t at_ = 0;
};

/// A list packed as its length and its items, `item(io, x)` each: one call for the
/// writer and the reader, as with operator().
template <class IO, class List, class Item>
void each_of(IO& io, List& list, Item&& item) {
  long n = static_cast<long>(list.size());
  io(n);
  if constexpr (std::is_same_v<IO, ByteReader>) list.resize(io.items(n));
  for (auto& x : list) item(io, x);
}

}  // namespace kelvin
