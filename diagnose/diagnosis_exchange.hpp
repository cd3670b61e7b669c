#pragma once
/// \file
/// What one rank of a diagnosis computes alone and every rank needs (a refit, the
/// missing force), packed for spread_tasks (base/spread_tasks.hpp).
#include "base/bytes.hpp"
#include "diagnose/diagnosis.hpp"

namespace kelvin {

void put(ByteWriter& out, const RefitResult& r);
void get(ByteReader& in, RefitResult& r);
void put(ByteWriter& out, const MissingForce& f);
void get(ByteReader& in, MissingForce& f);

}  // namespace kelvin
