#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "base/error.hpp"
#include "engine/csv.hpp"

namespace {

std::string data(const std::string& name) {
  return std::string(KELVIN_TEST_DATA) + "/csv/" + name;
}

/// Runs `f`, expecting a kelvin::Error whose message starts with "<path>:<line>:".
template <class F>
void expect_error_at(F f, const std::string& name, int line, const std::string& fragment = "") {
  const std::string path = data(name);
  try {
    f(path);
    FAIL() << name << ": expected an error at line " << line;
  } catch (const kelvin::Error& e) {
    const std::string msg = e.what();
    const std::string prefix = line > 0 ? path + ":" + std::to_string(line) + ": " : path + ": ";
    EXPECT_EQ(msg.rfind(prefix, 0), 0u) << "message: " << msg << "\nexpected prefix: " << prefix;
    if (!fragment.empty()) {
      EXPECT_NE(msg.find(fragment), std::string::npos) << msg;
    }
  }
}

TEST(MarkerRest, ReadsHeaderCommentsAndBlankLines) {
  const auto r = kelvin::read_marker_rest(data("rest_ok.csv"));
  ASSERT_EQ(r.names.size(), 2u);
  EXPECT_EQ(r.names[0], "tip");
  EXPECT_EQ(r.names[1], "mid");
  ASSERT_EQ(r.positions.cols(), 2);
  EXPECT_DOUBLE_EQ(r.positions(0, 0), 0.001);
  EXPECT_DOUBLE_EQ(r.positions(1, 0), 0.002);
  EXPECT_DOUBLE_EQ(r.positions(2, 0), 0.2);
  EXPECT_DOUBLE_EQ(r.positions(0, 1), -1.5e-3);
  EXPECT_DOUBLE_EQ(r.positions(1, 1), 0.0);
  EXPECT_DOUBLE_EQ(r.positions(2, 1), 0.1);
}

TEST(MarkerRest, NoHeaderAndCrlf) {
  const auto r = kelvin::read_marker_rest(data("rest_noheader_crlf.csv"));
  ASSERT_EQ(r.names.size(), 2u);
  EXPECT_EQ(r.names[1], "b");
  EXPECT_DOUBLE_EQ(r.positions(0, 0), 1.0);
  EXPECT_DOUBLE_EQ(r.positions(2, 1), 6.0);
}

TEST(MarkerRest, Errors) {
  auto rd = [](const std::string& p) { kelvin::read_marker_rest(p); };
  expect_error_at(rd, "rest_duplicate.csv", 5, "'a'");
  expect_error_at(rd, "rest_bad_number.csv", 3, "5x");
  expect_error_at(rd, "rest_bad_columns.csv", 2);
}

TEST(MarkerRest, MissingFile) {
  const std::string path = data("does_not_exist.csv");
  try {
    kelvin::read_marker_rest(path);
    FAIL();
  } catch (const kelvin::Error& e) {
    EXPECT_EQ(std::string(e.what()), path + ": cannot open (No such file or directory)");
  }
}

// Spreadsheet programs begin a UTF-8 CSV with a byte-order mark.
TEST(MarkerTracks, AByteOrderMarkIsIgnored) {
  const auto a = kelvin::read_marker_tracks(data("tracks_ok.csv"));
  const auto b = kelvin::read_marker_tracks(data("tracks_bom.csv"));
  EXPECT_EQ(a.names, b.names);
  EXPECT_EQ(a.times, b.times);
  ASSERT_EQ(a.xyz.size(), b.xyz.size());
  for (long k = 0; k < a.xyz.size(); ++k)
    if (std::isnan(a.xyz(k)))
      EXPECT_TRUE(std::isnan(b.xyz(k)));
    else
      EXPECT_EQ(a.xyz(k), b.xyz(k));
}

TEST(MarkerTracks, ReadsOcclusionAsNaN) {
  const auto m = kelvin::read_marker_tracks(data("tracks_ok.csv"));
  ASSERT_EQ(m.names.size(), 2u);
  EXPECT_EQ(m.names[0], "tip");
  EXPECT_EQ(m.names[1], "mid");
  ASSERT_EQ(m.times.size(), 3u);
  EXPECT_DOUBLE_EQ(m.times[0], 0.0);
  EXPECT_DOUBLE_EQ(m.times[1], 0.005556);
  EXPECT_DOUBLE_EQ(m.times[2], 0.02);
  ASSERT_EQ(m.xyz.rows(), 6);
  ASSERT_EQ(m.xyz.cols(), 3);
  EXPECT_DOUBLE_EQ(m.xyz(0, 0), 0.0012);
  EXPECT_DOUBLE_EQ(m.xyz(1, 0), 0.0003);
  EXPECT_DOUBLE_EQ(m.xyz(2, 0), 0.1998);
  EXPECT_DOUBLE_EQ(m.xyz(5, 0), 0.1);
  // Frame 1: tip_y, tip_z empty and mid_y "NaN".
  EXPECT_DOUBLE_EQ(m.xyz(0, 1), 0.0013);
  EXPECT_TRUE(std::isnan(m.xyz(1, 1)));
  EXPECT_TRUE(std::isnan(m.xyz(2, 1)));
  EXPECT_DOUBLE_EQ(m.xyz(3, 1), 1e-3);
  EXPECT_TRUE(std::isnan(m.xyz(4, 1)));
  EXPECT_DOUBLE_EQ(m.xyz(5, 1), 0.1);
  // Frame 2: tip fully occluded (lower-case nan).
  for (int k = 0; k < 3; ++k) EXPECT_TRUE(std::isnan(m.xyz(k, 2)));
  EXPECT_DOUBLE_EQ(m.xyz(4, 2), -4.5e-4);
  EXPECT_DOUBLE_EQ(m.xyz(5, 2), 0.1001);
}

TEST(MarkerTracks, Errors) {
  auto rd = [](const std::string& p) { kelvin::read_marker_tracks(p); };
  expect_error_at(rd, "tracks_bad_columns.csv", 3);
  expect_error_at(rd, "tracks_non_numeric.csv", 4, "two");
  expect_error_at(rd, "tracks_time.csv", 4, "does not increase");
  expect_error_at(rd, "tracks_header_order.csv", 1);
  expect_error_at(rd, "tracks_no_header.csv", 2);
}

TEST(ClampCsv, NormalisesAndKeepsQuaternionSignsConsistent) {
  const auto c = kelvin::read_clamp_csv(data("clamp_ok.csv"));
  ASSERT_EQ(c.t.size(), 3u);
  ASSERT_EQ(c.translation.size(), 3u);
  ASSERT_EQ(c.quaternion_wxyz.size(), 3u);
  EXPECT_DOUBLE_EQ(c.t[1], 0.5);
  EXPECT_DOUBLE_EQ(c.translation[2].x(), 0.02);
  EXPECT_DOUBLE_EQ(c.translation[2].y(), 0.001);
  EXPECT_NEAR((c.quaternion_wxyz[0] - Eigen::Vector4d(1, 0, 0, 0)).norm(), 0, 1e-15);
  // Row 1 (norm 1.0004, as rounded output writes) is normalised; (-0.6,0,0,-0.8) is
  // flipped to stay near (1,0,0,0); (-0.6,0,0.8,0) then flipped again.
  EXPECT_NEAR((c.quaternion_wxyz[1] - Eigen::Vector4d(0.6, 0, 0, 0.8)).norm(), 0, 1e-15);
  EXPECT_NEAR((c.quaternion_wxyz[2] - Eigen::Vector4d(0.6, 0, -0.8, 0)).norm(), 0, 1e-15);
  for (size_t i = 1; i < 3; ++i) EXPECT_GE(c.quaternion_wxyz[i].dot(c.quaternion_wxyz[i - 1]), 0.0);
}

TEST(ClampCsv, Errors) {
  auto rd = [](const std::string& p) { kelvin::read_clamp_csv(p); };
  expect_error_at(rd, "clamp_zero_q.csv", 2, "quaternion");
  // Norm 2 is a wrong column or convention, not a rotation to normalise silently.
  expect_error_at(rd, "clamp_scaled_q.csv", 3, "has norm 2, not 1");
  expect_error_at(rd, "clamp_time.csv", 5, "does not increase");
  expect_error_at(rd, "clamp_bad_columns.csv", 3);
  expect_error_at(rd, "clamp_one_row.csv", 0, "2 rows");
}

}  // namespace
