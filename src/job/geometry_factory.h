// Builds the microgeometry of a job from its [geometry] table (kinds: flat, sine-grating,
// binary-grating, ridged, gaussian, noise, hemispheres, axicon, overhang, mesh, heightfield).
#pragma once
#include <memory>
#include <string>

#include "geometry/microgeometry.h"
#include "geometry/topography_conditioning.h"
#include "job/params.h"

namespace mbsdf {

// A file named in the job, relative to the job file's folder unless absolute.
std::string resolvePath(const std::string& base, const std::string& file);

// What a heightfield geometry (or a surface with fabrication defects) was made from: the grid that
// was meshed and how a measured one was conditioned (`check` computes its texture parameters).
struct TopographyReport {
  std::shared_ptr<const Topography> heights;
  ConditioningReport conditioning;
};

Microgeometry buildMicrogeometry(const ParamDict& geo, const std::string& baseDir, std::string* kindOut,
                                 TopographyReport* topographyOut = nullptr);

// The most triangles a generator may make (1e7 unless set; a job asking for more fails naming the
// key to change). The job fuzzer lowers it so that each input stays a fraction of a second under
// the sanitizers: a valid 1e7-facet job takes about 80 s there, and it is linear work, not a hang.
double maxGeneratedTriangles();
void setMaxGeneratedTriangles(double n);

}  // namespace mbsdf
