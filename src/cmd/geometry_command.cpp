// `microbsdf geometry JOB.toml -o patch.ply`: the job's microgeometry patch, as the run sees it.
#include <iostream>

#include "cmd/command.h"
#include "core/error.h"
#include "geometry/microgeometry.h"
#include "job/job.h"

namespace mbsdf {

Command addGeometryCommand(CLI::App& app) {
  struct Options {
    std::string jobPath, outPath;
  };
  auto o = std::make_shared<Options>();
  Command c;
  c.app = app.add_subcommand("geometry", "write the job's microgeometry patch as PLY");
  c.app->add_option("job", o->jobPath, "job file (TOML)")->required();
  c.app->add_option("-o,--output", o->outPath, "patch.ply")->required();
  c.run = [o] {
    Job job = loadJob(o->jobPath);
    if (job.statistical)
      throw InputError(o->jobPath + ": [geometry] kind = \"statistical\" has no explicit microgeometry to write");
    writePly(job.geometry, o->outPath);
    std::cerr << "wrote " << o->outPath << ": " << job.geometry.vertices.size() << " vertices, "
              << job.geometry.triangles.size() << " triangles, " << job.geometry.sizeX << " x " << job.geometry.sizeY
              << " µm, z in [" << job.geometry.zMin() << ", " << job.geometry.zMax() << "] µm\n";
    return 0;
  };
  return c;
}

}  // namespace mbsdf
