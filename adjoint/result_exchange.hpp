#pragma once
/// \file
/// An experiment's evaluation packed for the ranks that did not run it: its result
/// and how it integrated (the EvaluationPlan it updated), so that every rank holds
/// what a serial run would, bit for bit; and a Gauss–Newton system one rank computed.
#include "adjoint/evaluation_plan.hpp"
#include "adjoint/experiment.hpp"
#include "adjoint/uncertainty.hpp"
#include "base/bytes.hpp"

namespace kelvin {

void put(ByteWriter& out, const ExperimentResult& r);
void get(ByteReader& in, ExperimentResult& r);
void put(ByteWriter& out, const EvaluationPlan& plan);
void get(ByteReader& in, EvaluationPlan& plan);
void put(ByteWriter& out, const GaussNewtonSystem& g);
void get(ByteReader& in, GaussNewtonSystem& g);

}  // namespace kelvin
