// Surfstand SDF (ISO 25178-71, after Blunt & Jiang's "Surface Data File" of the SURFSTAND project,
// 2003): a text header of `Key = value` lines (ASCII files, version "aBCR-…"), or a packed 81-byte
// header (binary files, "bBCR-…": version[8], manufacturer[10], created[12], modified[12],
// NumPoints and NumProfiles as uint16, Xscale, Yscale, Zscale, Zresolution as double, Compression,
// DataType, CheckType as uint8, little endian), then NumProfiles rows of NumPoints values,
// z = value · Zscale in metres, Xscale and Yscale the pitch in metres. DataType: 0 uint8, 1 uint16,
// 2 uint32, 3 float, 4 int8, 5 int16, 6 int32, 7 double. A non-finite value is a point not measured.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/error.h"
#include "geometry/topography.h"
#include "geometry/topography_header.h"

namespace mbsdf {
namespace {

static_assert(std::endian::native == std::endian::little, "the SDF binary reader assumes a little-endian host");

constexpr size_t kBinaryHeaderBytes = 8 + 10 + 12 + 12 + 2 * 2 + 4 * 8 + 3;

struct SdfHeader {
  int64_t numPoints = 0, numProfiles = 0;
  double xscale = 0, yscale = 0, zscale = 0;
  int compression = 0, dataType = 0, checkType = 0;
};

size_t bytesOf(int type) {
  static const size_t sizes[] = {1, 2, 4, 4, 1, 2, 4, 8};
  return sizes[type];
}

double rawValue(const char* p, int type) {
  auto get = [p](auto v) {
    std::memcpy(&v, p, sizeof v);
    return double(v);
  };
  switch (type) {
    case 0:
      return get(uint8_t{});
    case 1:
      return get(uint16_t{});
    case 2:
      return get(uint32_t{});
    case 3:
      return get(float{});
    case 4:
      return get(int8_t{});
    case 5:
      return get(int16_t{});
    case 6:
      return get(int32_t{});
    default:
      return get(double{});
  }
}

void checkHeader(const std::string& path, const SdfHeader& h) {
  if (h.dataType < 0 || h.dataType > 7)
    throw InputError(path + ": DataType " + std::to_string(h.dataType) + " is not an SDF data type (0 to 7)");
  if (h.compression != 0)
    throw InputError(path + ": Compression = " + std::to_string(h.compression) + " is not supported (0 only)");
  if (h.checkType != 0)
    throw InputError(path + ": CheckType = " + std::to_string(h.checkType) + " is not supported (0 only)");
  if (!(h.xscale > 0) || !(h.yscale > 0) || !std::isfinite(h.xscale) || !std::isfinite(h.yscale))
    throw InputError(path + ": Xscale and Yscale (the pitch in metres) must be positive");
  if (!(h.zscale != 0) || !std::isfinite(h.zscale)) throw InputError(path + ": Zscale must be a non-zero number");
  checkTopographySize(path, h.numPoints, h.numProfiles);
}

Topography topographyOf(const std::string& path, const SdfHeader& h) {
  Topography t;
  t.nx = int(h.numPoints);
  t.ny = int(h.numProfiles);
  t.dx_um = h.xscale * 1e6;
  t.dy_um = h.yscale * 1e6;
  t.source = path;
  t.z_um.assign(t.size(), 0.0);
  t.valid.assign(t.size(), 1);
  return t;
}

void store(Topography& t, size_t k, double raw, double zscale) {
  const double z_m = raw * zscale;
  if (std::isfinite(z_m))
    t.z_um[k] = z_m * 1e6;
  else
    t.valid[k] = 0;
}

Topography readBinary(const std::string& path, const std::string& bytes) {
  if (bytes.size() < kBinaryHeaderBytes)
    throw InputError(path + ": " + std::to_string(bytes.size()) + " bytes, shorter than a binary SDF header (" +
                     std::to_string(kBinaryHeaderBytes) + ")");
  const char* p = bytes.data() + 42;
  SdfHeader h;
  uint16_t n16;
  std::memcpy(&n16, p, 2);
  h.numPoints = n16;
  std::memcpy(&n16, p + 2, 2);
  h.numProfiles = n16;
  std::memcpy(&h.xscale, p + 4, 8);
  std::memcpy(&h.yscale, p + 12, 8);
  std::memcpy(&h.zscale, p + 20, 8);
  h.compression = static_cast<unsigned char>(p[36]);
  h.dataType = static_cast<unsigned char>(p[37]);
  h.checkType = static_cast<unsigned char>(p[38]);
  checkHeader(path, h);
  const size_t need = size_t(h.numPoints) * size_t(h.numProfiles) * bytesOf(h.dataType);
  if (bytes.size() < kBinaryHeaderBytes + need)
    throw InputError(path + ": " + std::to_string(h.numPoints) + " x " + std::to_string(h.numProfiles) +
                     " points of DataType " + std::to_string(h.dataType) + " need " + std::to_string(need) +
                     " bytes after the header; the file has " + std::to_string(bytes.size() - kBinaryHeaderBytes));
  Topography t = topographyOf(path, h);
  const char* data = bytes.data() + kBinaryHeaderBytes;
  for (size_t k = 0; k < t.size(); ++k) store(t, k, rawValue(data + k * bytesOf(h.dataType), h.dataType), h.zscale);
  return t;
}

Topography readText(const std::string& path, const std::string& bytes) {
  std::istringstream in(bytes);
  std::string line;
  std::getline(in, line);  // the version
  int lineNo = 1;
  KeyValueHeader keys(path, "SDF");
  bool ended = false;
  while (std::getline(in, line)) {
    ++lineNo;
    if (trimmed(line).rfind('*', 0) == 0) {
      ended = true;
      break;
    }
    keys.add(line, lineNo);  // a line without '=': free text, which some writers put in the header
  }
  if (!ended) throw InputError(path + ": the SDF header does not end with a line '*'");
  SdfHeader h;
  h.numPoints = keys.integer("NumPoints");
  h.numProfiles = keys.integer("NumProfiles");
  h.xscale = keys.number("Xscale");
  h.yscale = keys.number("Yscale");
  h.zscale = keys.number("Zscale");
  auto code = [&](const char* name) {  // a small code: no silent wrap-around into range
    const int64_t v = keys.integer(name, 0);
    if (v != int64_t(int(v))) throw InputError(path + ": " + name + " = " + std::to_string(v) + " is out of range");
    return int(v);
  };
  h.compression = code("Compression");
  h.dataType = code("DataType");
  h.checkType = code("CheckType");
  checkHeader(path, h);
  // Each value takes at least two characters (a digit and a separator): a header promising more
  // values than the text can hold is refused before the grid is allocated.
  const size_t rest = bytes.size() - size_t(in.tellg() < 0 ? bytes.size() : size_t(in.tellg()));
  if (size_t(h.numPoints) * size_t(h.numProfiles) > rest / 2 + 1)
    throw InputError(path + ": NumPoints x NumProfiles = " + std::to_string(h.numPoints * h.numProfiles) +
                     " values cannot fit in the " + std::to_string(rest) + " bytes after the header");
  Topography t = topographyOf(path, h);
  size_t k = 0;
  std::string token;
  while (k < t.size() && std::getline(in, line)) {
    ++lineNo;
    std::istringstream words(line);
    while (words >> token) {
      if (token == "*") break;
      if (k == t.size()) break;
      const std::optional<double> v = parseWhole<double>(token);
      if (!v) throw InputError(path + ": line " + std::to_string(lineNo) + ": '" + token + "' is not a height value");
      store(t, k++, *v, h.zscale);
    }
    if (token == "*") break;
  }
  if (k != t.size())
    throw InputError(path + ": " + std::to_string(k) +
                     " height values; NumPoints x NumProfiles = " + std::to_string(t.size()));
  return t;
}

}  // namespace

Topography readSdf(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path + ": cannot open the SDF file");
  std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (bytes.empty()) throw InputError(path + ": the SDF file is empty");
  Topography t = bytes[0] == 'b'   ? readBinary(path, bytes)
                 : bytes[0] == 'a' ? readText(path, bytes)
                                   : throw InputError(path +
                                                      ": not an SDF file (the version must start with 'a' "
                                                      "(text) or 'b' (binary), e.g. aBCR-1.0)");
  if (t.invalidCount() == 0) t.valid.clear();
  return t;
}

}  // namespace mbsdf
