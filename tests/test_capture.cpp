// Capture import: the C3D reader against the point-for-point CSV conversions of the
// silicone beam's captures, every C3D number format on files written here, Motive's
// CSV export, the registration, and the release of a body from rest.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

#include "base/error.hpp"
#include "capture/c3d_reader.hpp"
#include "capture/conversion.hpp"
#include "capture/motion_start.hpp"
#include "capture/registration.hpp"
#include "test_support.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;
const std::string kBeam = std::string(KELVIN_SOURCE_DIR) + "/yaml/examples/silicone-beam/";

// ---- a minimal C3D writer, for files in each processor's number formats ----------
enum class Proc { kIntel = 84, kDec = 85, kMips = 86 };

struct Writer {
  Proc proc;
  std::vector<unsigned char> bytes;
  void u8(int v) { bytes.push_back(static_cast<unsigned char>(v)); }
  void i16(int v) {
    const auto w = static_cast<uint16_t>(static_cast<int16_t>(v));
    if (proc == Proc::kMips) {
      u8(w >> 8);
      u8(w & 0xff);
    } else {
      u8(w & 0xff);
      u8(w >> 8);
    }
  }
  void f32(float v) {
    uint32_t bits;
    if (proc == Proc::kDec) {
      // VAX F: the same bits read as IEEE are 4× the value; word order swapped.
      const float ieee = v * 4;
      std::memcpy(&bits, &ieee, 4);
      if (v == 0) bits = 0;
      const uint16_t hi = bits >> 16, lo = bits & 0xffff;
      u8(hi & 0xff);
      u8(hi >> 8);
      u8(lo & 0xff);
      u8(lo >> 8);
      return;
    }
    std::memcpy(&bits, &v, 4);
    if (proc == Proc::kMips)
      for (int s = 24; s >= 0; s -= 8) u8(bits >> s & 0xff);
    else
      for (int s = 0; s <= 24; s += 8) u8(bits >> s & 0xff);
  }
  void pad_to_block() {
    while (bytes.size() % 512) u8(0);
  }
};

/// A C3D file of `xyz` ((3 × points) × frames, mm, NaN = invalid), integer or float.
std::vector<unsigned char> c3d(Proc proc, bool floats, const std::vector<std::string>& labels,
                               const Eigen::MatrixXd& xyz, double rate, float scale) {
  const int points = static_cast<int>(labels.size()), frames = static_cast<int>(xyz.cols());
  const float s = floats ? -std::abs(scale) : std::abs(scale);
  Writer w{proc, {}};
  // Header (block 1).
  w.u8(2);
  w.u8(0x50);
  w.i16(points);
  w.i16(0);
  w.i16(1);
  w.i16(frames);
  w.i16(10);
  w.f32(s);
  w.i16(4);  // data start block
  w.i16(0);
  w.f32(static_cast<float>(rate));
  w.pad_to_block();
  // Parameter section (blocks 2–3): the POINT group and its parameters.
  w.u8(1);
  w.u8(0x50);
  w.u8(2);
  w.u8(static_cast<int>(proc));
  const auto record = [&](const std::string& name, int id, int type, std::vector<int> dims,
                          const std::function<void()>& data, size_t data_bytes, bool last) {
    w.u8(static_cast<int>(name.size()));
    w.u8(id & 0xff);
    for (char c : name) w.u8(c);
    const size_t size = type == 0 ? 3 : 2 + 2 + dims.size() + data_bytes + 1;
    w.i16(last ? 0 : static_cast<int>(size));
    if (type != 0) {
      w.u8(type & 0xff);
      w.u8(static_cast<int>(dims.size()));
      for (int d : dims) w.u8(d);
      data();
    }
    w.u8(0);  // description length
  };
  size_t len = 0;
  for (const auto& l : labels) len = std::max(len, l.size());
  record(
      "POINT", -1, 0, {}, [] {}, 0, false);
  record(
      "USED", 1, 2, {}, [&] { w.i16(points); }, 2, false);
  record(
      "SCALE", 1, 4, {}, [&] { w.f32(s); }, 4, false);
  record(
      "RATE", 1, 4, {}, [&] { w.f32(static_cast<float>(rate)); }, 4, false);
  record(
      "UNITS", 1, -1, {2}, [&] { w.u8('m'), w.u8('m'); }, 2, false);
  record(
      "LABELS", 1, -1, {static_cast<int>(len), points},
      [&] {
        for (const auto& l : labels)
          for (size_t k = 0; k < len; ++k) w.u8(k < l.size() ? l[k] : ' ');
      },
      len * labels.size(), true);
  w.pad_to_block();
  while (w.bytes.size() < 3 * 512) w.u8(0);
  // Point data (block 4 on).
  for (int k = 0; k < frames; ++k)
    for (int i = 0; i < points; ++i) {
      const bool valid = !xyz.col(k).segment<3>(3 * i).hasNaN();
      for (int a = 0; a < 3; ++a) {
        const double v = valid ? xyz(3 * i + a, k) : 0;
        if (floats)
          w.f32(static_cast<float>(v));
        else
          w.i16(static_cast<int>(std::lround(v / scale)));
      }
      if (floats)
        w.f32(valid ? 0.0f : -1.0f);
      else
        w.i16(valid ? 0 : -1);
    }
  w.pad_to_block();
  return w.bytes;
}

std::string write_bytes(const fs::path& path, const std::vector<unsigned char>& b) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
  return path.string();
}

}  // namespace

// The beam's three captures (Qualisys, float, Intel) against their CSV conversions,
// which were written with 6 decimals in metres.
TEST(C3d, ReadsTheSiliconeBeamCapturesAsTheirCsvConversions) {
  for (const char* name : {"beam_gravity_V2_a", "beam_load52_V2_a", "beam_load101_V2_a"}) {
    SCOPED_TRACE(name);
    const Capture c = read_c3d(kBeam + name + ".c3d");
    const MarkerTracks csv =
        read_marker_tracks(std::string(KELVIN_TEST_DATA) + "/capture/" + name + ".csv");
    EXPECT_EQ(c.format, "C3D (Intel, float)");
    EXPECT_DOUBLE_EQ(c.rate, 100);
    ASSERT_EQ(c.markers.names, csv.names);
    ASSERT_EQ(c.markers.times.size(), csv.times.size());
    double worst = 0;
    int occluded = 0;
    for (long k = 0; k < csv.xyz.cols(); ++k) {
      EXPECT_NEAR(c.markers.times[k], csv.times[k], 1e-6);
      for (long r = 0; r < csv.xyz.rows(); ++r) {
        ASSERT_EQ(std::isnan(c.markers.xyz(r, k)), std::isnan(csv.xyz(r, k))) << r << " " << k;
        if (std::isnan(csv.xyz(r, k))) {
          ++occluded;
          continue;
        }
        worst = std::max(worst, std::abs(c.markers.xyz(r, k) - csv.xyz(r, k)));
      }
    }
    EXPECT_LE(worst, 0.5e-6 + 1e-9);  // the CSV's rounding to 1 µm
    RecordProperty(std::string(name) + "_occluded", occluded);
  }
}

// Every processor's byte order and float format, integer data scaled, invalid
// points occluded, labels trimmed and made column names.
TEST(C3d, ReadsIntelDecAndMipsFilesInFloatAndIntegerFormat) {
  const fs::path dir = test::scratch("c3d-formats");
  const std::vector<std::string> labels = {"Tip - 1", "base", "LongerName42"};
  Eigen::MatrixXd xyz(9, 5);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-900, 900);
  for (long k = 0; k < xyz.size(); ++k) xyz(k) = u(rng);
  xyz.col(3).segment<3>(3).setConstant(NAN);  // "base" not seen in frame 3
  const float scale = 0.05f;
  for (Proc p : {Proc::kIntel, Proc::kDec, Proc::kMips})
    for (bool floats : {true, false}) {
      SCOPED_TRACE(testing::Message() << static_cast<int>(p) << (floats ? " float" : " integer"));
      const std::string path =
          write_bytes(dir / fmt::format("p{}{}.c3d", static_cast<int>(p), floats ? "f" : "i"),
                      c3d(p, floats, labels, xyz, 250, scale));
      const Capture c = read_c3d(path);
      ASSERT_EQ(c.markers.names, (std::vector<std::string>{"Tip_-_1", "base", "LongerName42"}));
      EXPECT_DOUBLE_EQ(c.rate, 250);
      ASSERT_EQ(c.markers.xyz.cols(), 5);
      EXPECT_NEAR(c.markers.times[4], 4 / 250.0, 1e-12);
      for (long k = 0; k < 5; ++k)
        for (long r = 0; r < 9; ++r) {
          if (std::isnan(xyz(r, k))) {
            EXPECT_TRUE(std::isnan(c.markers.xyz(r, k)));
            continue;
          }
          // float: single precision; integer: the scale's quantum
          const double tol = floats ? 1e-7 * std::abs(xyz(r, k)) : 0.5 * scale;
          EXPECT_NEAR(c.markers.xyz(r, k), 1e-3 * xyz(r, k), 1e-3 * tol) << r << " " << k;
        }
    }
}

TEST(C3d, TruncatedAndForeignFilesAreRefusedWithTheirName) {
  const fs::path dir = test::scratch("c3d-bad");
  std::ifstream in(kBeam + "beam_gravity_V2_a.c3d", std::ios::binary);
  std::vector<unsigned char> b((std::istreambuf_iterator<char>(in)), {});
  b.resize(b.size() / 2);
  const std::string truncated = write_bytes(dir / "half.c3d", b);
  try {
    read_c3d(truncated);
    FAIL() << "a truncated file was read";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("half.c3d: truncated C3D file"), std::string::npos)
        << e.what();
  }
  const std::string text = write_bytes(dir / "text.c3d", {'h', 'e', 'l', 'l', 'o'});
  EXPECT_THROW(read_c3d(text), Error);
  b.assign(512 * 3, 0);
  b[0] = 2, b[1] = 0x50, b[512 + 3] = 99;
  try {
    read_c3d(write_bytes(dir / "proc.c3d", b));
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("processor type 99"), std::string::npos) << e.what();
  }
}

TEST(MotiveCsv, ReadsMarkersAndRigidBodiesInMetres) {
  const fs::path dir = test::scratch("motive");
  const std::string path = (dir / "take.csv").string();
  test::write_text(path,
                   "Format Version,1.23,Take Name,Take 1,Capture Frame Rate,120.000000,Export "
                   "Frame Rate,120.000000,Rotation Type,Quaternion,Length Units,Millimeters,"
                   "Coordinate Space,Global\n"
                   "\n"
                   ",Type,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Rigid "
                   "Body,Rigid Body,Marker,Marker,Marker\n"
                   ",Name,Grip,Grip,Grip,Grip,Grip,Grip,Grip,Grip,Tip,Tip,Tip\n"
                   ",ID,1,1,1,1,1,1,1,1,2,2,2\n"
                   ",,Rotation,Rotation,Rotation,Rotation,Position,Position,Position,Mean Marker "
                   "Error,Position,Position,Position\n"
                   "Frame,Time (Seconds),X,Y,Z,W,X,Y,Z,,X,Y,Z\n"
                   "0,0.000000,0,0,0,1,10,20,30,0.1,100,200,300\n"
                   "1,0.008333,0,0,0.7071068,0.7071068,11,20,30,0.1,,,\n"
                   "2,0.016667,0,0,1,0,12,20,30,0.1,101,200,300\n");
  const Capture c = read_capture(path);
  EXPECT_EQ(c.format, "Motive CSV 1.23");
  EXPECT_DOUBLE_EQ(c.rate, 120);
  ASSERT_EQ(c.markers.names, std::vector<std::string>{"Tip"});
  EXPECT_NEAR(c.markers.xyz(0, 0), 0.1, 1e-15);
  EXPECT_NEAR(c.markers.xyz(2, 2), 0.3, 1e-15);
  EXPECT_TRUE(std::isnan(c.markers.xyz(1, 1)));
  ASSERT_EQ(c.bodies.size(), 1u);
  EXPECT_EQ(c.bodies[0].name, "Grip");
  EXPECT_NEAR(c.bodies[0].pose(0, 2), 0.012, 1e-15);
  EXPECT_NEAR(c.bodies[0].pose(3, 1), 0.7071068, 1e-12);  // w

  // As a clamp motion: relative to the first pose, rotation about the world origin.
  ConversionOptions o;
  o.bodies = {"Grip"};
  o.markers = {"Tip"};
  o.start = ConversionOptions::Start::kTime;  // three frames: no still window to find
  const Conversion conv = convert_capture(c, o, path);
  ASSERT_EQ(conv.clamps.size(), 1u);
  const ClampSamples& s = conv.clamps[0].second;
  ASSERT_EQ(s.t.size(), 3u);
  // Frame 2: a half turn about z at (0.012, 0.02, 0.03) from the start pose at
  // (0.01, 0.02, 0.03): a point of the body at the start pose's origin ends there.
  const Eigen::Quaterniond q(s.quaternion_wxyz[2][0], s.quaternion_wxyz[2][1],
                             s.quaternion_wxyz[2][2], s.quaternion_wxyz[2][3]);
  const Eigen::Vector3d moved = q * Eigen::Vector3d(0.01, 0.02, 0.03) + s.translation[2];
  EXPECT_NEAR((moved - Eigen::Vector3d(0.012, 0.02, 0.03)).norm(), 0, 1e-9);
}

TEST(MotiveCsv, ABadCellNamesItsLineAndColumn) {
  const fs::path dir = test::scratch("motive-bad");
  const std::string path = (dir / "take.csv").string();
  test::write_text(path,
                   "Format Version,1.23,Length Units,Meters\n"
                   ",Type,Marker,Marker,Marker\n,Name,A,A,A\n,,Position,Position,Position\n"
                   "Frame,Time (Seconds),X,Y,Z\n0,0,1,2,3\n1,0.01,1,x2,3\n");
  try {
    read_capture(path);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("take.csv:7: column 4 ('Y'): 'x2'"), std::string::npos)
        << e.what();
  }
}

// Kabsch recovers a known transform exactly, and refuses collinear markers.
TEST(Registration, RecoversARigidTransformAndReportsResiduals) {
  Eigen::Matrix3Xd a(3, 5);
  a << 0, 1, 0, 0, 0.3, 0, 0, 1, 0, 0.2, 0, 0, 0, 1, 0.7;
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::Vector3d t(0.1, -0.2, 0.3);
  Eigen::Matrix3Xd b = (R * a).colwise() + t;
  const Registration r = fit_registration(a, b, {"a", "b", "c", "d", "e"});
  EXPECT_LT((r.R - R).norm(), 1e-12);
  EXPECT_LT((r.t - t).norm(), 1e-12);
  EXPECT_LT(r.rms(), 1e-12);
  b(0, 4) += 1e-3;  // one marker 1 mm off: its residual carries most of it
  const Registration off = fit_registration(a, b, {"a", "b", "c", "d", "e"});
  EXPECT_GT(off.residual.col(4).norm(), off.residual.col(0).norm());
  Eigen::Matrix3Xd line(3, 3);
  line << 0, 1, 2, 0, 1, 2, 0, 1, 2;
  EXPECT_THROW(fit_registration(line, line, {"a", "b", "c"}), Error);
}

// A synthetic release: markers still (with noise) until t₀ = 0.4537 s, then falling
// as ½ g (t − t₀)²; the fit finds t₀ to a fraction of the frame interval and a ≈ g.
TEST(MotionStart, FindsTheReleaseOfABodyFromRest) {
  MarkerTracks t;
  t.names = {"m"};
  const double t0 = 0.4537, g = 9.81, rate = 100, sigma = 5e-6;
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0, sigma);
  const int n = 120;
  t.xyz.resize(3, n);
  for (int k = 0; k < n; ++k) {
    const double time = k / rate;
    t.times.push_back(time);
    const double fall = time > t0 ? 0.5 * g * (time - t0) * (time - t0) : 0;
    t.xyz.col(k) << 0.1 + noise(rng), noise(rng), 0.03 - fall + noise(rng);
  }
  const MotionStart s = find_motion_start(t, {0});
  EXPECT_NEAR(s.noise, std::sqrt(3.0) * sigma, 0.3 * sigma);
  ASSERT_GE(s.onset, 0);
  EXPECT_GT(t.times[s.onset], t0);
  ASSERT_GE(s.fall_frames, 2);
  EXPECT_NEAR(s.release, t0, 1e-3);
  EXPECT_NEAR(s.acceleration, g, 0.1 * g);
}

// The real beam's three releases: t₀ lies between the last still frame and the first
// moving one, within 3 ms (a third of a frame) of the estimate that registered the
// bundled example (scripts/prepare_silicone_beam.py, another choice of fall frames),
// and the first frames fall with roughly g (three frames, 20-30 µm of noise).
TEST(MotionStart, TheSiliconeBeamIsReleasedFromRest) {
  const std::vector<std::pair<std::string, double>> cases = {
      {"beam_gravity_V2_a", 0.7063}, {"beam_load52_V2_a", 0.4290}, {"beam_load101_V2_a", 0.5070}};
  for (const auto& [name, script_t0] : cases) {
    SCOPED_TRACE(name);
    const Capture c = read_c3d(kBeam + name + ".c3d");
    std::vector<int> tips;
    for (int i = 0; i < static_cast<int>(c.markers.names.size()); ++i)
      if (c.markers.names[i].rfind("Tip", 0) == 0) tips.push_back(i);
    ASSERT_EQ(tips.size(), 3u);
    const MotionStart s = find_motion_start(c.markers, tips);
    ASSERT_GE(s.onset, 1);
    ASSERT_GE(s.fall_frames, 3);
    EXPECT_GE(s.release, c.markers.times[s.rest_frames - 1]);
    EXPECT_LT(s.release, c.markers.times[s.onset]);
    EXPECT_NEAR(s.release, script_t0, 3e-3);
    EXPECT_NEAR(s.acceleration, 9.81, 0.35 * 9.81);
    EXPECT_LT(s.noise, 0.05e-3);  // still Qualisys markers: tens of micrometres
  }
}

}  // namespace kelvin
