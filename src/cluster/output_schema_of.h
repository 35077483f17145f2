// The output file's schema (io/output_schema.h) of a job: what the run records of the job and
// which datasets it writes.
#pragma once
#include "io/output_schema.h"
#include "job/job.h"

namespace mbsdf {

OutputSchema outputSchemaOf(const Job& job);

}  // namespace mbsdf
