// Gwyddion Simple Field 1.0 (gwyddion.net, "Simple Field Files"): the line "Gwyddion Simple Field
// 1.0", `name = value` header lines, one to four NUL bytes aligning the data to a multiple of four,
// then XRes x YRes little-endian float32 values, row by row. XReal and YReal are the field's size in
// XYUnits, heights are in ZUnits; both must be lengths here (m, mm, um/µm, nm), since a height map
// without units would be scaled by guess. A non-finite value is a point not measured.
#include <bit>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>

#include "core/error.h"
#include "geometry/mesh_loader.h"
#include "geometry/topography.h"
#include "geometry/topography_header.h"

namespace mbsdf {
namespace {

static_assert(std::endian::native == std::endian::little, "the GSF reader assumes a little-endian host");

const std::string kMagic = "Gwyddion Simple Field 1.0\n";

// A GSF length unit to micrometres; Gwyddion writes "m" for topography.
double lengthUnit(const std::string& path, const std::string& key, const std::string& unit) {
  try {
    return unitToMicrometres(unit, path);
  } catch (const InputError&) {
    throw InputError(path + ": " + key + " = '" + unit + "' is not a length unit (m, mm, um, µm, nm)");
  }
}

}  // namespace

Topography readGsf(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path + ": cannot open the GSF file");
  std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (bytes.compare(0, kMagic.size(), kMagic) != 0)
    throw InputError(path + ": not a GSF file (it must start with the line 'Gwyddion Simple Field 1.0')");
  const size_t nul = bytes.find('\0', kMagic.size());
  if (nul == std::string::npos) throw InputError(path + ": the GSF header is not ended by NUL padding");
  KeyValueHeader keys(path, "GSF");
  int lineNo = 1;
  for (size_t pos = kMagic.size(); pos < nul;) {
    size_t end = bytes.find('\n', pos);
    if (end == std::string::npos || end > nul) end = nul;
    const std::string line = bytes.substr(pos, end - pos);
    ++lineNo;
    pos = end + 1;
    if (!trimmed(line).empty() && !keys.add(line, lineNo))
      throw InputError(path + ": line " + std::to_string(lineNo) + ": '" + trimmed(line) + "' is not 'name = value'");
  }
  const double xres = keys.number("XRes"), yres = keys.number("YRes");
  if (xres != std::floor(xres) || yres != std::floor(yres))
    throw InputError(path + ": XRes and YRes must be whole numbers");
  // Bounded before the conversion (one beyond int64, or an infinity, would be undefined); the
  // size check then says what the limits are.
  auto points = [](double res) { return int64_t(std::clamp(res, -1.0, double(kMaxTopographySide) + 1)); };
  checkTopographySize(path, points(xres), points(yres));
  const double xy_um = lengthUnit(path, "XYUnits", keys.text("XYUnits"));
  const double z_um = lengthUnit(path, "ZUnits", keys.text("ZUnits"));
  const double xreal = keys.number("XReal", 1.0), yreal = keys.number("YReal", 1.0);
  if (!(xreal > 0 && yreal > 0)) throw InputError(path + ": XReal and YReal must be positive");

  Topography t;
  t.nx = int(xres);
  t.ny = int(yres);
  t.dx_um = xreal * xy_um / t.nx;
  t.dy_um = yreal * xy_um / t.ny;
  t.source = path;
  const size_t dataStart = (nul / 4 + 1) * 4;  // the padding: one to four NULs up to a multiple of 4
  const size_t need = t.size() * 4;
  if (bytes.size() < dataStart || bytes.size() - dataStart != need)
    throw InputError(path + ": " + std::to_string(t.nx) + " x " + std::to_string(t.ny) + " float32 values need " +
                     std::to_string(need) + " bytes after the header; the file has " +
                     std::to_string(bytes.size() > dataStart ? bytes.size() - dataStart : 0));
  t.z_um.assign(t.size(), 0.0);
  t.valid.assign(t.size(), 1);
  for (size_t k = 0; k < t.size(); ++k) {
    float v;
    std::memcpy(&v, bytes.data() + dataStart + 4 * k, 4);
    if (std::isfinite(v))
      t.z_um[k] = double(v) * z_um;
    else
      t.valid[k] = 0;
  }
  if (t.invalidCount() == 0) t.valid.clear();
  return t;
}

}  // namespace mbsdf
