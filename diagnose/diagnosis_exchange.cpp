#include "diagnose/diagnosis_exchange.hpp"

namespace kelvin {
namespace {

// Every field, in one order for the writer and the reader.

template <class IO>
void strings(IO& io, auto& list) {
  each_of(io, list, [](IO& bytes, auto& s) { bytes(s); });
}

template <class IO>
void named(IO& io, auto& values) {
  each_of(io, values, [](IO& bytes, auto& v) {
    bytes(v.name);
    bytes(v.value);
    bytes(v.std_error);
  });
}

template <class IO>
void misfit(IO& io, auto& f) {
  io(f.ok);
  io(f.error);
  io(f.rms);
  io(f.sum_sq);
  io(f.samples);
  io(f.residual);
  each_of(io, f.entries, [](IO& bytes, auto& sample) { bytes(sample); });
}

template <class IO>
void refit_fields(IO& io, auto& r) {
  io(r.candidate);
  io(r.on_top_of);
  io(r.ok);
  io(r.error);
  io(r.evaluations);
  io(r.seconds);
  misfit(io, r.train);
  io(r.statistic);
  io(r.threshold);
  io(r.dof);
  io(r.bic);
  each_of(io, r.heldout, [](IO& bytes, auto& h) {
    bytes(h.path);
    strings(bytes, h.marker_names);
    misfit(bytes, h.before);
    misfit(bytes, h.after);
  });
  io(r.heldout_drop);
  io(r.heldout_threshold);
  io(r.passes_training);
  io(r.passes_heldout);
  io(r.at_nominal);
  io(r.where);
  named(io, r.parameters);
  named(io, r.nominal_parameters);
  io(r.errors_note);
  io(r.fitted_yaml);
  io(r.p);
  strings(io, r.labels);
}

template <class IO>
void missing_force_fields(IO& io, auto& f) {
  io(f.ok);
  io(f.error);
  io(f.knots);
  io(f.segments);
  io(f.evaluations);
  io(f.seconds);
  io(f.rms_before);
  io(f.rms_after);
  io(f.statistic);
  io(f.threshold);
  io(f.dof);
  io(f.peak_time);
  io(f.where);
  each_of(io, f.regions, [](IO& bytes, auto& region) {
    bytes(region.name);
    bytes(region.rms_force);
    bytes(region.share);
  });
  strings(io, f.files);
}

}  // namespace

void put(ByteWriter& out, const RefitResult& r) {
  refit_fields(out, r);
}
void get(ByteReader& in, RefitResult& r) {
  refit_fields(in, r);
}
void put(ByteWriter& out, const MissingForce& f) {
  missing_force_fields(out, f);
}
void get(ByteReader& in, MissingForce& f) {
  missing_force_fields(in, f);
}

}  // namespace kelvin
