// Builds the microgeometry of a job from its [geometry] table (kinds: flat, sine-grating,
// binary-grating, ridged, gaussian, noise, hemispheres, axicon, overhang, mesh, heightfield).
#pragma once
#include <string>

#include "geometry/microgeometry.h"
#include "job/params.h"

namespace mbsdf {

Microgeometry buildMicrogeometry(const ParamDict& geo, const std::string& baseDir, std::string* kindOut);

}  // namespace mbsdf
