// `kelvin capture`: a C3D or Motive CSV capture turned into kelvin's track CSV in the
// model frame, from the start of the motion, with its rest positions.
#include <fmt/format.h>

#include <filesystem>

#include "base/error.hpp"
#include "capture/conversion.hpp"
#include "drivers/commands.hpp"
#include "engine/output.hpp"

namespace kelvin {
namespace {

struct Args {
  std::string capture, output, layout, rest, start = "capture";
  std::vector<std::string> markers, moving, clamps;
  double duration = 0;
};

std::vector<std::string> split_names(const std::vector<std::string>& items) {
  std::vector<std::string> out;
  for (const auto& item : items) {
    size_t a = 0;
    for (;;) {
      const size_t b = item.find(',', a);
      const std::string name = item.substr(a, b == std::string::npos ? std::string::npos : b - a);
      if (!name.empty()) out.push_back(track_name(name));
      if (b == std::string::npos) break;
      a = b + 1;
    }
  }
  return out;
}

void print_conversion(const Capture& cap, const Conversion& c, const Args& a) {
  const MarkerTracks& t = cap.markers;
  fmt::print("capture: {}: {}, {} markers, {} frames at {:g} Hz ({:.3f} s), lengths in {}\n",
             a.capture, cap.format, t.names.size(), t.times.size(), cap.rate,
             t.times.empty() ? 0.0 : t.times.back(), cap.units);
  const MotionStart& m = c.motion;
  fmt::print("still: {} frames, noise {:.4f} mm RMS; motion = displacement > {:.4f} mm",
             m.still_frames, 1e3 * m.noise, 1e3 * m.threshold);
  if (m.onset >= 0)
    fmt::print(", first at t = {:.4f} s\n", t.times[m.onset]);
  else
    fmt::print(": none\n");
  if (m.fall_frames > 0)
    fmt::print("release from rest: t0 = {:.4f} s (½a(t − t0)² over {} frames, a = {:.2f} m/s²)\n",
               m.release, m.fall_frames, m.acceleration);
  if (c.registration) {
    const Registration& r = *c.registration;
    fmt::print("registration (capture → model, least squares over {} markers):\n", r.names.size());
    for (size_t i = 0; i < r.names.size(); ++i)
      fmt::print("  {:<16} residual {:7.3f} mm  ({:+.3f}, {:+.3f}, {:+.3f})\n", r.names[i],
                 1e3 * r.residual.col(i).norm(), 1e3 * r.residual(0, i), 1e3 * r.residual(1, i),
                 1e3 * r.residual(2, i));
    fmt::print("  RMS {:.3f} mm; x_model = R x_capture + t, R rows:\n", 1e3 * r.rms());
    for (int i = 0; i < 3; ++i)
      fmt::print("    [{:+.6f} {:+.6f} {:+.6f}]\n", r.R(i, 0), r.R(i, 1), r.R(i, 2));
    fmt::print("  t = [{:+.6f} {:+.6f} {:+.6f}] m\n", r.t[0], r.t[1], r.t[2]);
  }
  fmt::print("start: capture time {:.4f} s is t = 0\n", c.start);
  for (size_t i = 0; i < c.tracks.names.size(); ++i)
    fmt::print("  {:<16} rest ({:.3f}, {:.3f}, {:.3f}) mm, seen in {:.1f} % of the frames\n",
               c.tracks.names[i], 1e3 * c.rest(0, i), 1e3 * c.rest(1, i), 1e3 * c.rest(2, i),
               100 * c.seen[i]);
}

}  // namespace

void register_capture(CLI::App& app, int& exit_code) {
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "capture",
      "Convert a motion capture (C3D from Vicon, Qualisys, ...; OptiTrack Motive CSV) into "
      "kelvin's marker tracks: registered to the model frame by named markers, from the start "
      "of the motion, in metres and seconds.");
  cmd->add_option("capture", a->capture, "C3D file or Motive CSV export")->required();
  cmd->add_option("-o,--output", a->output, "tracks CSV to write (t,name_x,name_y,name_z,...)")
      ->required();
  cmd->add_option("--layout", a->layout,
                  "CSV name,x,y,z: model-frame positions (m) of markers at rest, to register "
                  "the capture frame to the model frame (at least 3; e.g. markers on a fixed "
                  "clamp)");
  cmd->add_option("--markers", a->markers, "markers to write (comma-separated; default: all)");
  cmd->add_option("--moving", a->moving,
                  "markers whose motion marks the start (default: the written ones)");
  cmd->add_option("--start", a->start,
                  "t = 0 at: 'capture' (its first frame), 'release' (a release from rest, "
                  "from the ½at² growth of the first displacement), 'motion' (the last frame "
                  "at rest), or a capture time in s")
      ->capture_default_str();
  cmd->add_option("--duration", a->duration, "seconds after the start to write (default: all)")
      ->check(positive_number(true));
  cmd->add_option("--rest", a->rest, "also write the markers' rest positions (CSV name,x,y,z)");
  cmd->add_option("--clamp", a->clamps,
                  "BODY=FILE: a rigid body's motion relative to its pose at the start, as a "
                  "clamp motion CSV (t,tx,ty,tz,qw,qx,qy,qz)");
  cmd->callback([a, &exit_code] {
    try {
      ConversionOptions o;
      if (!a->layout.empty()) o.layout = read_marker_rest(a->layout);
      if (o.layout)
        for (auto& n : o.layout->names) n = track_name(n);
      o.markers = split_names(a->markers);
      o.moving = split_names(a->moving);
      o.duration = a->duration;
      if (a->start == "capture") {
        o.start = ConversionOptions::Start::kCapture;
      } else if (a->start == "release") {
        o.start = ConversionOptions::Start::kRelease;
      } else if (a->start == "motion") {
        o.start = ConversionOptions::Start::kMotion;
      } else {
        double t = 0;
        if (!parse_csv_number(a->start, t) || !std::isfinite(t))
          throw Error(fmt::format(
              "--start: '{}' is neither capture, release, motion nor a time in s", a->start));
        o.start = ConversionOptions::Start::kTime;
        o.start_time = t;
      }
      std::vector<std::pair<std::string, std::string>> clamp_files;
      for (const auto& item : a->clamps) {
        const auto eq = item.find('=');
        if (eq == std::string::npos || eq == 0 || eq + 1 == item.size())
          throw Error(fmt::format("--clamp: '{}' is not BODY=FILE", item));
        clamp_files.push_back({track_name(item.substr(0, eq)), item.substr(eq + 1)});
        o.bodies.push_back(clamp_files.back().first);
      }
      const Capture cap = read_capture(a->capture);
      const Conversion c = convert_capture(cap, o, a->capture);
      print_conversion(cap, c, *a);
      write_file_atomic(a->output, tracks_csv(c.tracks));
      fmt::print("wrote {}: {} frames, t = {:.4f} … {:.4f} s\n", a->output, c.tracks.times.size(),
                 c.tracks.times.front(), c.tracks.times.back());
      if (!a->rest.empty()) {
        write_file_atomic(a->rest, rest_csv(c.tracks.names, c.rest));
        fmt::print("wrote {}: rest positions of {} markers\n", a->rest, c.tracks.names.size());
      }
      for (size_t k = 0; k < c.clamps.size(); ++k) {
        write_file_atomic(clamp_files[k].second, clamp_csv(c.clamps[k].second));
        fmt::print("wrote {}: motion of rigid body '{}', {} poses\n", clamp_files[k].second,
                   c.clamps[k].first, c.clamps[k].second.t.size());
      }
    } catch (const Error& e) {
      fmt::print(stderr, "error: {}\n", e.what());
      exit_code = kExitInputError;
    } catch (const std::exception& e) {
      fmt::print(stderr, "error: {}\n", e.what());
      exit_code = kExitInputError;
    }
  });
}

}  // namespace kelvin
