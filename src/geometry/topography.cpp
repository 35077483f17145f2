#include "geometry/topography.h"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "core/error.h"
#include "geometry/mesh_loader.h"

namespace mbsdf {

size_t Topography::invalidCount() const {
  return valid.empty() ? 0 : size_t(std::count(valid.begin(), valid.end(), uint8_t(0)));
}

namespace {
std::string lowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}
}  // namespace

bool isTopographyFile(const std::string& path) {
  const std::string ext = lowerExtension(path);
  return ext == ".x3p" || ext == ".sdf" || ext == ".gsf";
}

void checkTopographySize(const std::string& path, int64_t nx, int64_t ny) {
  if (nx < 2 || ny < 2 || nx > kMaxTopographySide || ny > kMaxTopographySide ||
      double(nx) * double(ny) > kMaxTopographyPoints)
    throw InputError(path + ": a grid of " + std::to_string(nx) + " x " + std::to_string(ny) +
                     " points; a height map needs at least 2 per side, at most " + std::to_string(kMaxTopographySide) +
                     " per side and 1e8 in all");
}

Topography loadTopography(const std::string& path) {
  if (!std::filesystem::exists(path)) throw InputError(path + ": topography file not found");
  const std::string ext = lowerExtension(path);
  if (ext == ".x3p") return readX3p(path);
  if (ext == ".sdf") return readSdf(path);
  if (ext == ".gsf") return readGsf(path);
  throw InputError(path + ": unknown topography format '" + ext + "' (x3p, sdf, gsf; exr with texel_um)");
}

Topography loadTopographyExr(const std::string& path, double texel_um) {
  Topography t;
  t.z_um = loadHeightfieldExr(path, &t.nx, &t.ny);
  t.dx_um = t.dy_um = texel_um;
  t.source = path;
  return t;
}

}  // namespace mbsdf
