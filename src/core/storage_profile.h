// How the output file stores its BSDF tables (docs/output.md "Storage profiles"): the values in
// single precision, or in half precision scaled per slice and channel, rounded to their noise or
// kept to the last bit; the standard errors per bin, or only per slice (the file's /stats); the
// spectrum as computed, or its colour (CIE 1931 XYZ or linear sRGB, core/colour.h); each pair of
// incidence bins once or both ways. A value type shared by the job (which parses it from [output])
// and the writer.
#pragma once
#include <string>

namespace mbsdf {

// (The order of each set is that of its names in the job keys: job.cpp parses them by index.)
enum class TableValues { Float32, Float16 };
enum class TableErrors { PerBin, PerSlice };
enum class TableColour { Spectral, Xyz, LinearSrgb };
// Each same-side pair of incidence bins stored once (the mean of both estimates) or both ways.
enum class TablePairs { Both, Once };
// Each value rounded to its own standard error (io/noise_rounding.h), or every bit kept.
enum class TableRounding { Noise, None };

struct StorageProfile {
  TableValues values = TableValues::Float32;
  TableErrors errors = TableErrors::PerBin;
  TableColour colour = TableColour::Spectral;
  TablePairs pairs = TablePairs::Both;
  TableRounding rounding = TableRounding::Noise;
  std::string preset = "full";  // the [output] profile these settings started from

  static StorageProfile full() { return {}; }
  static StorageProfile compact() {
    return {TableValues::Float16, TableErrors::PerSlice, TableColour::Xyz,
            TablePairs::Once,     TableRounding::Noise,  "compact"};
  }
  bool operator==(const StorageProfile&) const = default;
  bool spectral() const { return colour == TableColour::Spectral; }
  static const char* colourName(TableColour c) {
    return c == TableColour::Xyz ? "xyz" : c == TableColour::LinearSrgb ? "linear-srgb" : "spectral";
  }
  // "compact (values = float16, rounding = noise, …)": the preset and what it became.
  std::string name() const {
    return preset + " (values = " + (values == TableValues::Float16 ? "float16" : "float32") +
           ", rounding = " + (rounding == TableRounding::Noise ? "noise" : "none") +
           ", errors = " + (errors == TableErrors::PerSlice ? "per-slice" : "per-bin") +
           ", colour = " + colourName(colour) + ", pairs = " + (pairs == TablePairs::Once ? "once" : "both") + ")";
  }
};

}  // namespace mbsdf
