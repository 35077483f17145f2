// Tables for the preview's tests, written through the program's own writer: a slice per listed
// incidence (φ = 0), its bins filled by a closed form, the file declared isotropic so that the lookup
// turns any incidence onto them; and the table of a statistical surface computed as `run` computes
// it.
#pragma once
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "cluster/output_schema_of.h"
#include "io/bsdf_file.h"
#include "job/job.h"
#include "job/tile_computer.h"

namespace mbsdf::test {

inline std::string renderTestPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("microbsdf_render_" + name + ".h5")).string();
}

inline std::string incidenceList(const std::vector<double>& theta_deg) {
  std::string s = "[";
  for (double t : theta_deg) s += (s.size() > 1 ? ", [" : "[") + std::to_string(t) + ", 0.0]";
  return s + "]";
}

// fBin(wi, bin) for every bin of each incidence's slice (the slices `written` says, all by default; a
// list without a rule between its incidences when not `isotropic`; `comment` heads the job's text), 16 wavelengths over
// 400–700 nm, the same value at each: a grey table. grid: the [directions] keys of the grid, e.g. "n_theta = 45\nn_phi
// = 180" or "grid = \"disk\"\nwidth = 64".
inline std::string writeGreyTable(const std::string& name, const std::string& grid_keys,
                                  const std::vector<double>& theta_deg,
                                  const std::function<double(const Vec3&, int, const DirectionGrid&)>& fBin,
                                  bool isotropic = true, const std::function<bool(int)>& written = {},
                                  const std::string& comment = "") {
  const Job job =
      loadJobFromString("# " + comment + "\n[directions]\n" + grid_keys + "\nincidence = " + incidenceList(theta_deg) +
                            "\n[spectrum]\nwavelengths_nm = { min = 400.0, max = 700.0, count = 16 }\n"
                            "[effects]\ncomponents = [\"coherent\"]\n[output]\nrounding = \"none\"\n",
                        "render-test.toml", "");
  const DirectionGrid grid(job.gridLayout);
  OutputSchema schema = outputSchemaOf(job);
  if (isotropic) schema.symmetry = "isotropic (declared by the test)";
  const std::string path = renderTestPath(name);
  std::filesystem::remove(path);
  BsdfFileWriter w(path, schema, grid);
  const int nL = 16, nB = grid.binCount();
  for (int i = 0; i < int(theta_deg.size()); ++i) {
    if (written && !written(i)) continue;
    TileResult r;
    r.incidenceIndex = i;
    r.incidenceBin = job.incidence[size_t(i)].bin;
    r.nLambda = nL;
    r.nBins = nB;
    r.samples = 1;
    r.value[int(Component::Coherent)].assign(size_t(nL) * nB, 0.0);
    r.stdError[int(Component::Coherent)].assign(size_t(nL) * nB, 0.0);
    const Vec3 wi = sphericalDirection(radians(theta_deg[size_t(i)]), 0.0);
    for (int b = 0; b < nB; ++b) {
      const double f = fBin(wi, b, grid);
      for (int l = 0; l < nL; ++l) r.at(Component::Coherent, l, b) = f;
    }
    r.truncated = r.leaked = r.missed = std::vector<double>(size_t(nL), 0.0);
    w.writeTile(r);
  }
  w.finish();
  return path;
}

// A flat mirror's bin values: all the light in the exit bin of the mirror direction of wi (shared by
// the two bins beside it when it lies on their edge, as φ = 180° does on a theta-phi grid).
inline double mirrorBin(const Vec3& wi, int b, const DirectionGrid& g) {
  const Vec3 m{-wi.x, -wi.y, wi.z};
  const int hit = g.binOf(m), beside = g.binOf(turnedAboutZ(m, -1e-9));
  if (b != hit && b != beside) return 0.0;
  return (hit == beside ? 1.0 : 0.5) / g.projectedSolidAngle(b);
}

// A job's table computed tile by tile as `run` does, on one process.
inline std::string computeTable(const std::string& name, const std::string& jobText) {
  Job job = loadJobFromString(jobText, name + ".toml", "");
  const DirectionGrid grid(job.gridLayout);
  const std::string path = renderTestPath(name);
  std::filesystem::remove(path);
  BsdfFileWriter w(path, outputSchemaOf(job), grid);
  const TileComputer computer(job, grid);
  double pathSeconds = 0, waveSeconds = 0;
  for (int t = 0; t < int(job.incidence.size()); ++t)
    w.writeTile(computer.compute(
        t, [](uint64_t) {}, &pathSeconds, &waveSeconds));
  w.finish();
  return path;
}

}  // namespace mbsdf::test
