#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <regex>
#include <sstream>

#include "base/error.hpp"
#include "engine/csv.hpp"
#include "engine/output.hpp"

namespace fs = std::filesystem;

namespace {

/// A fresh scratch directory per test, removed afterwards.
class OutputTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / ("kelvin_test_output_" + std::to_string(::getpid())) /
           info->name();
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_.parent_path()); }

  static std::string slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
  }
  /// Names of leftover temp files (`*.tmp.*`) anywhere under dir_.
  std::vector<std::string> temp_files() const {
    std::vector<std::string> out;
    for (const auto& e : fs::recursive_directory_iterator(dir_))
      if (e.path().filename().string().find(".tmp.") != std::string::npos)
        out.push_back(e.path().string());
    return out;
  }

  fs::path dir_;
};

TEST_F(OutputTest, AtomicWriteReplacesAndLeavesNoTempFile) {
  const std::string path = (dir_ / "a.txt").string();
  kelvin::write_file_atomic(path, "first version\n");
  EXPECT_EQ(slurp(path), "first version\n");
  std::string binary("x\0y\n\r\n", 6);
  kelvin::write_file_atomic(path, binary);
  EXPECT_EQ(slurp(path), binary);
  EXPECT_TRUE(temp_files().empty());
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 1);
}

TEST_F(OutputTest, AtomicWriteErrorNamesPathAndReason) {
  const std::string path = (dir_ / "missing_dir" / "a.txt").string();
  try {
    kelvin::write_file_atomic(path, "x");
    FAIL();
  } catch (const kelvin::Error& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.rfind(path + ":", 0), 0u) << msg;
    EXPECT_NE(msg.find(std::strerror(ENOENT)), std::string::npos) << msg;
  }
  EXPECT_FALSE(fs::exists(dir_ / "missing_dir"));
}

TEST_F(OutputTest, MarkerCsvRoundTrip) {
  const std::string path = (dir_ / "markers.csv").string();
  kelvin::MarkerCsvWriter w(path, {"tip", "mid"});
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Eigen::Matrix3Xd p(3, 2);
  p << 0.00123, -0.5, 0.0004, 1e-7, 0.2, 123.456;
  w.add_frame(0.0, p);
  Eigen::Matrix3Xd q = p;
  q.col(1).setConstant(nan);  // occluded marker survives as NaN
  w.add_frame(0.005556, q);
  Eigen::Matrix3Xd r(3, 2);
  r << 1.0 / 3, 2.0 / 3, -std::sqrt(2.0), 1e-20, 0, 7;
  w.add_frame(0.01, r);
  EXPECT_EQ(w.frames(), 3);
  w.flush();
  EXPECT_TRUE(temp_files().empty());

  const auto m = kelvin::read_marker_tracks(path);
  ASSERT_EQ(m.names, (std::vector<std::string>{"tip", "mid"}));
  ASSERT_EQ(m.times.size(), 3u);
  EXPECT_EQ(m.times[1], 0.005556);
  // ≤ 9 significant digits survive %.9g exactly.
  for (int k = 0; k < 6; ++k) EXPECT_EQ(m.xyz(k, 0), p(k % 3, k / 3)) << k;
  for (int k = 0; k < 3; ++k) EXPECT_EQ(m.xyz(k, 1), p(k, 0));
  for (int k = 3; k < 6; ++k) EXPECT_TRUE(std::isnan(m.xyz(k, 1)));
  for (int k = 0; k < 6; ++k) {
    const double v = r(k % 3, k / 3);
    EXPECT_NEAR(m.xyz(k, 2), v, 5e-9 * std::abs(v)) << k;
  }
  EXPECT_EQ(slurp(path).substr(0, 39), "t,tip_x,tip_y,tip_z,mid_x,mid_y,mid_z\n0");

  // flush() rewrites the whole file, not appending.
  w.add_frame(0.02, p);
  w.flush();
  EXPECT_EQ(kelvin::read_marker_tracks(path).times.size(), 4u);
  EXPECT_THROW(w.add_frame(0.03, Eigen::Matrix3Xd::Zero(3, 3)), kelvin::Error);
}

kelvin::Mesh two_tets() {
  kelvin::Mesh m;
  m.nodes.resize(3, 5);
  m.nodes << 0, 1, 0, 0, 1,  //
      0, 0, 1, 0, 1,         //
      0, 0, 0, 1, 1;
  m.tets.resize(4, 2);
  m.tets << 0, 1,  //
      1, 2,        //
      2, 3,        //
      3, 4;
  m.region = {3, 7};
  m.source = "two tets";
  return m;
}

struct ArrayInfo {
  std::string type, name;
  int comps = 0;
  std::uint64_t offset = 0;
};

/// Raw bytes of one appended block, checked against its UInt64 header.
template <class T>
std::vector<T> block(const std::string& appended, const ArrayInfo& a, size_t count) {
  std::uint64_t size = 0;
  std::memcpy(&size, appended.data() + a.offset, sizeof size);
  EXPECT_EQ(size, count * sizeof(T)) << a.name;
  std::vector<T> out(count);
  std::memcpy(out.data(), appended.data() + a.offset + 8, count * sizeof(T));
  return out;
}

TEST_F(OutputTest, VtuByteLayoutAndPvdSeries) {
  const auto mesh = two_tets();
  const fs::path out = dir_ / "nested" / "vtk";  // created on demand
  kelvin::VtuSeries series(out.string(), "run", mesh);
  Eigen::Matrix3Xd x = mesh.nodes, v(3, 5);
  x(0, 4) += 0.25;
  x(2, 1) -= 0.125;
  for (int i = 0; i < 15; ++i) v.data()[i] = 0.5 * i - 1;
  Eigen::VectorXd energy(2), mu(2);
  energy << 1.5, -2.25;
  mu << 1e5, 2e5;
  series.write_frame(0.0, mesh.nodes, Eigen::Matrix3Xd::Zero(3, 5), {});
  series.write_frame(0.125, x, v, {{"energy", energy}, {"mu", mu}});
  EXPECT_EQ(series.frames(), 2);
  EXPECT_TRUE(temp_files().empty());
  ASSERT_TRUE(fs::exists(out / "run_00000.vtu"));
  ASSERT_TRUE(fs::exists(out / "run_00001.vtu"));

  const std::string doc = slurp(out / "run_00001.vtu");
  const std::string marker = "<AppendedData encoding=\"raw\">";
  const size_t ad = doc.find(marker);
  ASSERT_NE(ad, std::string::npos);
  const size_t underscore = doc.find('_', ad + marker.size());
  ASSERT_NE(underscore, std::string::npos);
  const std::string header = doc.substr(0, ad);
  EXPECT_NE(header.find("type=\"UnstructuredGrid\""), std::string::npos);
  EXPECT_NE(header.find("header_type=\"UInt64\""), std::string::npos);
  EXPECT_NE(header.find("byte_order=\"LittleEndian\""), std::string::npos);
  EXPECT_NE(header.find("NumberOfPoints=\"5\" NumberOfCells=\"2\""), std::string::npos);

  std::map<std::string, ArrayInfo> arrays;
  const std::regex re(
      "<DataArray type=\"(\\w+)\" Name=\"(\\w+)\" NumberOfComponents=\"(\\d+)\" "
      "format=\"appended\" offset=\"(\\d+)\"/>");
  for (std::sregex_iterator it(header.begin(), header.end(), re), end; it != end; ++it)
    arrays[(*it)[2]] = {(*it)[1], (*it)[2], std::stoi((*it)[3]), std::stoull((*it)[4])};
  ASSERT_EQ(arrays.size(), 9u);
  const std::map<std::string, std::pair<std::string, int>> expected = {
      {"points", {"Float64", 3}},   {"displacement", {"Float64", 3}},
      {"velocity", {"Float64", 3}}, {"connectivity", {"Int64", 1}},
      {"offsets", {"Int64", 1}},    {"types", {"UInt8", 1}},
      {"region", {"Int32", 1}},     {"energy", {"Float64", 1}},
      {"mu", {"Float64", 1}}};
  for (const auto& [name, tc] : expected) {
    ASSERT_TRUE(arrays.count(name)) << name;
    EXPECT_EQ(arrays[name].type, tc.first) << name;
    EXPECT_EQ(arrays[name].comps, tc.second) << name;
  }

  // The blocks tile the appended section exactly: each starts where the previous ended.
  const std::string tail = "\n  </AppendedData>\n</VTKFile>\n";
  ASSERT_GE(doc.size(), underscore + 1 + tail.size());
  EXPECT_EQ(doc.substr(doc.size() - tail.size()), tail);
  const std::string appended =
      doc.substr(underscore + 1, doc.size() - tail.size() - (underscore + 1));
  std::vector<std::uint64_t> offsets;
  for (const auto& [name, a] : arrays) offsets.push_back(a.offset);
  std::sort(offsets.begin(), offsets.end());
  EXPECT_EQ(offsets.front(), 0u);
  for (size_t k = 0; k < offsets.size(); ++k) {
    std::uint64_t size;
    ASSERT_LE(offsets[k] + 8, appended.size());
    std::memcpy(&size, appended.data() + offsets[k], 8);
    const std::uint64_t next = k + 1 < offsets.size() ? offsets[k + 1] : appended.size();
    EXPECT_EQ(offsets[k] + 8 + size, next) << "block " << k;
  }

  const auto pts = block<double>(appended, arrays["points"], 15);
  const auto disp = block<double>(appended, arrays["displacement"], 15);
  const auto vel = block<double>(appended, arrays["velocity"], 15);
  for (int i = 0; i < 15; ++i) {
    EXPECT_EQ(pts[i], x.data()[i]);
    EXPECT_EQ(disp[i], x.data()[i] - mesh.nodes.data()[i]);
    EXPECT_EQ(vel[i], v.data()[i]);
  }
  EXPECT_EQ(disp[12], 0.25);   // node 4, x
  EXPECT_EQ(disp[5], -0.125);  // node 1, z
  EXPECT_EQ(block<std::int64_t>(appended, arrays["connectivity"], 8),
            (std::vector<std::int64_t>{0, 1, 2, 3, 1, 2, 3, 4}));
  EXPECT_EQ(block<std::int64_t>(appended, arrays["offsets"], 2), (std::vector<std::int64_t>{4, 8}));
  EXPECT_EQ(block<std::uint8_t>(appended, arrays["types"], 2), (std::vector<std::uint8_t>{10, 10}));
  EXPECT_EQ(block<std::int32_t>(appended, arrays["region"], 2), (std::vector<std::int32_t>{3, 7}));
  EXPECT_EQ(block<double>(appended, arrays["energy"], 2), (std::vector<double>{1.5, -2.25}));
  EXPECT_EQ(block<double>(appended, arrays["mu"], 2), (std::vector<double>{1e5, 2e5}));

  const std::string pvd = slurp(out / "run.pvd");
  EXPECT_NE(pvd.find("type=\"Collection\""), std::string::npos);
  const std::regex ds("<DataSet timestep=\"([^\"]+)\"[^>]* file=\"([^\"]+)\"/>");
  std::vector<std::pair<double, std::string>> sets;
  for (std::sregex_iterator it(pvd.begin(), pvd.end(), ds), end; it != end; ++it)
    sets.emplace_back(std::stod((*it)[1]), (*it)[2]);
  ASSERT_EQ(sets.size(), 2u);
  EXPECT_EQ(sets[0], (std::pair<double, std::string>{0.0, "run_00000.vtu"}));
  EXPECT_EQ(sets[1], (std::pair<double, std::string>{0.125, "run_00001.vtu"}));
}

TEST_F(OutputTest, VtuRefusesMismatchedSizes) {
  const auto mesh = two_tets();
  kelvin::VtuSeries series(dir_.string(), "bad", mesh);
  EXPECT_THROW(
      series.write_frame(0, Eigen::Matrix3Xd::Zero(3, 4), Eigen::Matrix3Xd::Zero(3, 5), {}),
      kelvin::Error);
  EXPECT_THROW(series.write_frame(0, mesh.nodes, Eigen::Matrix3Xd::Zero(3, 5),
                                  {{"f", Eigen::VectorXd::Zero(3)}}),
               kelvin::Error);
  EXPECT_EQ(series.frames(), 0);
  EXPECT_FALSE(fs::exists(dir_ / "bad.pvd"));
}

}  // namespace
