// How the output file stores its BSDF tables (docs/output.md "Storage profiles"): the values in
// single precision, or in half precision scaled per slice and wavelength; the standard errors per
// bin, or only per slice (the file's /stats). A value type shared by the job (which parses it from
// [output]) and the writer.
#pragma once
#include <string>

namespace mbsdf {

enum class TableValues { Float32, Float16 };
enum class TableErrors { PerBin, PerSlice };

struct StorageProfile {
  TableValues values = TableValues::Float32;
  TableErrors errors = TableErrors::PerBin;

  static StorageProfile full() { return {}; }
  static StorageProfile compact() { return {TableValues::Float16, TableErrors::PerSlice}; }
  bool operator==(const StorageProfile&) const = default;
  // "full", "compact", or its settings ("values = float16, errors = per-bin").
  std::string name() const {
    if (*this == full()) return "full";
    if (*this == compact()) return "compact";
    return std::string("values = ") + (values == TableValues::Float16 ? "float16" : "float32") +
           ", errors = " + (errors == TableErrors::PerSlice ? "per-slice" : "per-bin");
  }
};

}  // namespace mbsdf
