// `microbsdf report`: one self-contained HTML page about an output file, for a reader without the
// program: the job and its provenance, the effects planner's decisions and reasons, `info`'s table of
// energies and errors, a slider over incidence directions showing each model's slice (true colour
// and log2 false colour with its labelled scale), the plane-of-incidence lobes of the models at that
// incidence, each component's albedo against θi, and the material preview (render/preview.h).
// Everything is inside the file — images as data: URIs, the figures drawn by a short inline script
// from inline JSON — so it opens from disk with no server and no network.
#pragma once
#include <functional>
#include <string>

#include "io/bsdf_file.h"

namespace mbsdf {

struct ReportRequest {
  int sliceSize = 160;     // pixels of each slice picture
  int maxIncidences = 36;  // slider positions at most (spread over the finished incidences)
  int renderSize = 256;    // preview pixels per model; 0: no preview
  int renderSpp = 32;
  std::string shape = "sphere";
};

// The page; progress(what) is called as each part starts.
std::string htmlReport(const BsdfFileReader& file, const std::string& path, const ReportRequest& req,
                       const std::function<void(const std::string&)>& progress = {});

// The incidences the slider runs over: finished ones, those of the first finished azimuth when the
// file holds several azimuths and that leaves at least two, then evenly spread to at most `most`,
// in order of θ.
std::vector<int> reportIncidences(const BsdfFileReader& file, int most);

}  // namespace mbsdf
