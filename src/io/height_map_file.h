// The heights a heightfield job meshes, after reading and conditioning, as an HDF5 file for
// inspection (`microbsdf check JOB --heights FILE.h5`): /heights_um (rows y, columns x, double, the
// values the mesh is built from), attributes dx_um, dy_um and source. h5py reads it as it is.
#pragma once
#include <string>

#include "geometry/topography.h"

namespace mbsdf {

// Written to `<path>.partial` and renamed: an existing file is replaced whole or left as it was.
void writeHeightMap(const std::string& path, const Topography& t);

}  // namespace mbsdf
