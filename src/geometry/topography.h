// A height map on a regular grid, as surface metrology instruments (confocal microscopes,
// white-light interferometers, AFMs) export it: heights in micrometres, a texel pitch per axis, and
// the points the instrument could not measure. Read from ISO 25178-72 X3P, Surfstand SDF (ISO
// 25178-71), Gwyddion GSF or a float EXR image; conditioned (topography_conditioning.h) and then
// meshed by heightfieldMesh. Row j holds y = j·dy, column i holds x = i·dx, for every format.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace mbsdf {

struct Topography {
  int nx = 0, ny = 0;
  double dx_um = 0, dy_um = 0;  // texel pitch
  std::vector<double> z_um;     // z_um[j*nx + i]
  std::vector<uint8_t> valid;   // 1 where measured; empty when every point is
  std::string source;           // the file, for messages
  // What the reader accepted although the format's standard does not allow it (a layout or value
  // other readers accept), each naming the file: the caller logs them as warnings.
  std::vector<std::string> warnings;

  size_t size() const { return size_t(nx) * size_t(ny); }
  bool isValid(size_t k) const { return valid.empty() || valid[k] != 0; }
  size_t invalidCount() const;
};

// The formats, chosen by the file's extension (case-insensitive): .x3p, .sdf, .gsf. Lengths come
// from the file (metres there). Throws InputError naming the file (and the XML line or header key)
// on anything malformed. EXR images carry no pitch: loadTopographyExr takes it.
Topography loadTopography(const std::string& path);
Topography loadTopographyExr(const std::string& path, double texel_um);
bool isTopographyFile(const std::string& path);  // .x3p, .sdf, .gsf

// Sizes read from a file are checked before anything is allocated: at most this many points per side
// and in all (a 16k x 16k interferometer stitch is 2.7e8; beyond that the mesh would not fit).
constexpr int kMaxTopographySide = 65536;
constexpr double kMaxTopographyPoints = 1e8;
void checkTopographySize(const std::string& path, int64_t nx, int64_t ny);

// Per-format readers (topography_x3p.cpp, topography_sdf.cpp, topography_gsf.cpp).
Topography readX3p(const std::string& path);
Topography readSdf(const std::string& path);
Topography readGsf(const std::string& path);

}  // namespace mbsdf
