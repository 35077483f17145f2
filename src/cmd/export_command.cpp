// `microbsdf export OUT.h5 --format zemax|rgl|mbsdf -o FILE [--model WM] [--lambda-nm NM] [--colour C]`:
// a stored table in a format other tools read (export/zemax_bsdf.h, export/rgl_bsdf.h,
// export/mdl_mbsdf.h). Zemax and spectral MBSDF: one file per wavelength ("_<λ>nm" before FILE's
// extension when there are several); RGL: one file with every chosen wavelength; RGL and MBSDF
// --colour rgb: one linear sRGB file. Every file is written whole or not at all (an existing one is
// replaced only by a complete file).
#include <fmt/format.h>

#include <filesystem>
#include <iostream>

#include "cmd/command.h"
#include "core/error.h"
#include "export/mdl_mbsdf.h"
#include "export/rgl_bsdf.h"
#include "export/zemax_bsdf.h"
#include "io/bsdf_file.h"
#include "io/bsdf_lookup.h"
#include "io/output_target.h"

namespace mbsdf {
namespace {

// FILE, or FILE with "_<λ>nm" before its extension when the export writes several wavelengths.
std::string perWavelengthPath(const std::string& path, double lambda_nm, bool several) {
  if (!several) return path;
  const std::filesystem::path p(path);
  return (p.parent_path() / (p.stem().string() + fmt::format("_{:g}nm", lambda_nm) + p.extension().string())).string();
}

// Indices of the table's wavelengths named by --lambda-nm (all when none is named).
std::vector<int> wavelengthIndices(const BsdfFileReader& f, const std::vector<double>& lambda_nm,
                                   const std::string& h5Path) {
  const std::vector<double>& table = f.wavelengths_nm();
  std::vector<int> which;
  for (double l : lambda_nm) {
    int k = -1;
    for (size_t i = 0; i < table.size(); ++i)
      if (std::abs(table[i] - l) < 1e-6) k = int(i);
    if (k < 0)
      throw InputError("--lambda-nm " + fmt::format("{:g}", l) + ": not a wavelength of " + h5Path + " (" +
                       fmt::format("{}", fmt::join(table, ", ")) + " nm)");
    which.push_back(k);
  }
  if (which.empty())
    for (size_t i = 0; i < table.size(); ++i) which.push_back(int(i));
  return which;
}

// The lower medium's index over the upper's (real parts) at wavelength index k, from the table's own
// job text; k < 0: at the table's wavelength nearest 555 nm (an XYZ file shares one refracted centre).
double relativeIndex(const BsdfFileReader& f, int k, const std::string& h5Path) {
  const std::vector<double>& nm = f.wavelengths_nm();
  if (k < 0) {
    k = 0;
    for (size_t i = 0; i < nm.size(); ++i)
      if (std::abs(nm[i] - 555) < std::abs(nm[size_t(k)] - 555)) k = int(i);
  }
  const std::optional<Material> material = tableMaterial(f, h5Path);
  if (!material) throw InputError(h5Path + ": the file holds no job text to take the material from");
  const Material& m = *material;
  if (m.isConductor()) throw InputError(h5Path + ": a conductor transmits nothing: no BTDF to write");
  return m.ior(nm[size_t(k)] * 1e-3).real() / m.outsideIor;
}

void noteClamped(int clamped, int values) {
  if (clamped > 0)
    std::cerr << "note: " << clamped << " of " << values
              << " values were below 0 (Monte Carlo noise, or colours outside sRGB) and are stored as 0\n";
}

// What the file holds and what it approximates, quantified.
void reportMbsdf(const std::string& path, const std::string& model, const MbsdfFile& m) {
  std::cerr << "wrote " << path << " (model " << model
            << (m.transmission ? ", reflection and transmission" : ", reflection") << ", "
            << (m.bytes.size() + 512) / 1024 << " KiB)\n";
  std::cerr << fmt::format(
      "note: stored symmetric, as MDL runtimes read it, with each row's albedo the table's (it would have been "
      "off by {:.2f} % at most; left {:.1e})\n",
      100 * m.reflectionBalance.runtimeAlbedoError, m.reflectionBalance.residual);
  if (m.anisotropic && m.azimuths_deg.size() == 1)
    std::cerr << fmt::format(
        "warning: the table is anisotropic but holds incidences at one azimuth ({:g} deg): the isotropic MBSDF "
        "takes that plane of incidence for every one; how much anisotropy that loses is not measured\n",
        m.azimuths_deg[0]);
  else if (m.anisotropic)
    std::cerr << fmt::format(
        "warning: the table is anisotropic; the isotropic MBSDF holds its mean over the incidence azimuth, "
        "{:.1f} % of the table's L1 norm away from it\n",
        100 * m.anisotropyL1);
  const MbsdfBalance& t = m.transmissionBalance;
  if (m.transmission)
    std::cerr << fmt::format(
        "{}: transmission stored symmetric, as MDL runtimes read it, with each row's albedo the table's (a runtime "
        "would have been off by {:.1f} % at most; left {:.1e}); this BTDF is not reciprocal, and its lobe in the "
        "file differs from the table's by {:.1f} % of its L1 norm (docs/export.md)\n",
        t.lobeChangeL1 > 0.05 ? "warning" : "note", 100 * t.runtimeAlbedoError, t.residual, 100 * t.lobeChangeL1);
  if (std::max(m.reflectionBalance.residual, t.residual) > 1e-3)
    std::cerr << fmt::format(
        "warning: some row's albedo stays {:.2f} % from the table's: the symmetric table cannot carry it\n",
        100 * std::max(m.reflectionBalance.residual, t.residual));
  noteClamped(m.negativeClamped, m.values);
}

}  // namespace

Command addExportCommand(CLI::App& app) {
  struct Options {
    std::string h5Path, outPath, format = "zemax", model, colour = "spectral", side = "reflection";
    std::vector<double> lambda_nm;
  };
  auto o = std::make_shared<Options>();
  Command c;
  CLI::App* cmd = c.app =
      app.add_subcommand("export", "write a table in a format renderers or optical-design tools read");
  cmd->add_option("file", o->h5Path, "output HDF5 file")->required();
  cmd->add_option("--format", o->format,
                  "zemax: OpticStudio's tabular BSDF (BRDF, one wavelength per file); rgl: the RGL database's "
                  ".bsdf (Mitsuba 3, pbrt-v4; reflection); mbsdf: MDL's measured BSDF (reflection and "
                  "transmission, isotropic)")
      ->check(CLI::IsMember({"zemax", "rgl", "mbsdf"}))
      ->capture_default_str();
  cmd->add_option("--colour", o->colour,
                  "spectral (zemax, mbsdf: one file per wavelength; rgl: the table's wavelengths), rgb (rgl, "
                  "mbsdf: linear sRGB) or xyz (zemax: CIE tristimulus)")
      ->check(CLI::IsMember({"spectral", "rgb", "xyz"}))
      ->capture_default_str();
  cmd->add_option("--side", o->side,
                  "reflection, or transmission (zemax: a BTDF file; rgl holds a BRDF only; an mbsdf file holds both)")
      ->check(CLI::IsMember({"reflection", "transmission"}))
      ->capture_default_str();
  cmd->add_option("--model", o->model,
                  "GS, GM, WS, WM or a component name (default: the fullest model the file holds)");
  cmd->add_option("--lambda-nm", o->lambda_nm, "wavelengths to write, each one of the table's (default: all)");
  cmd->add_option("-o,--output", o->outPath, "the file to write (x.bsdf)")->required();
  c.run = [o] {
    checkOutputPath(o->outPath);  // before reading: an unusable location is named at once
    BsdfFileReader f(o->h5Path);
    const std::string model = modelOrFullest(f, o->model, o->h5Path);
    const BsdfLookup lookup(f, model);
    if (!f.spectral()) {
      // A table stored in colour (its storage profile) has no wavelengths to pick: it goes out as
      // the colour each format holds.
      if (!o->lambda_nm.empty())
        throw InputError("--lambda-nm: " + o->h5Path + " stores its tables in colour (" + f.colourSpace() +
                         "), not per wavelength");
      if (o->colour == "spectral") {
        o->colour = o->format == "zemax" ? "xyz" : "rgb";
        std::cerr << "note: " << o->h5Path << " stores its tables in colour (" << f.colourSpace() << "): writing "
                  << (o->colour == "xyz" ? "CIE XYZ" : "linear sRGB") << "\n";
      }
    }
    const std::vector<int> which =
        f.spectral() ? wavelengthIndices(f, o->lambda_nm, o->h5Path) : std::vector<int>{0, 1, 2};
    const bool transmission = o->side == "transmission";
    if (transmission && o->format != "zemax")
      throw InputError(
          o->format == "mbsdf"
              ? "--side transmission: an mbsdf file holds both sides of the table already; leave out --side"
              : "--side transmission: the rgl format holds reflection only (a BRDF)");
    const bool rgb = o->colour == "rgb", xyz = o->colour == "xyz";
    if (rgb && o->format == "zemax") throw InputError("--colour rgb: the zemax format holds one wavelength or XYZ");
    if (xyz && o->format != "zemax") throw InputError("--colour xyz: only the zemax format holds tristimulus values");
    if ((rgb || xyz) && !o->lambda_nm.empty())
      throw InputError("--colour " + o->colour + " uses every wavelength of the table: leave out --lambda-nm");
    warnIfIncomplete(f, "unfinished slices make the export fail");
    const std::string description = "microbsdf " + model + " of " + o->h5Path;
    if (o->format == "rgl") {
      RglExport e;
      e.wavelengths = which;
      e.colour = rgb ? RglExport::Colour::rgb : RglExport::Colour::spectral;
      const RglFile rgl = rglBsdfFile(f, lookup, e, description);
      writeFileAtomically(o->outPath, rgl.bytes);
      std::cerr << "wrote " << o->outPath << " (model " << model << ", " << (rgl.bytes.size() + 512) / 1024
                << " KiB)\n";
      std::cerr << fmt::format("note: each incidence scaled to the table's albedo: by {:.2f} % at most\n",
                               100 * rgl.energyCorrection);
      for (size_t i = 0; i < std::min<size_t>(rgl.unresolved.size(), 5); ++i) {
        const auto& u = rgl.unresolved[i];
        std::cerr << fmt::format(
            "warning: at theta_i {:g} deg, phi_i {:g} deg, {} the file reflects {:.3g} where the table reflects "
            "{:.3g}: the format's nodes do not resolve this lobe (left unscaled)\n",
            u.theta_deg, u.phi_deg, u.band, u.fileAlbedo, u.tableAlbedo);
      }
      if (rgl.unresolved.size() > 5) std::cerr << "warning: " << rgl.unresolved.size() - 5 << " more such incidences\n";
      noteClamped(rgl.negativeClamped, rgl.nodes);
      return 0;
    }
    const std::vector<int> files = rgb || xyz ? std::vector<int>{0} : which;
    for (int k : files) {
      const std::string path = perWavelengthPath(o->outPath, f.wavelengths_nm()[size_t(k)], files.size() > 1);
      if (o->format == "zemax") {
        ZemaxExport e = defaultZemaxExport();
        e.wavelength = k;
        e.xyz = xyz;
        e.transmission = transmission;
        if (transmission) e.eta = relativeIndex(f, xyz ? -1 : k, o->h5Path);
        writeFileAtomically(path, zemaxBsdfText(f, lookup, e, o->h5Path));
        std::cerr << "wrote " << path << " (model " << model << ", "
                  << (xyz ? std::string("CIE XYZ") : fmt::format("{:g} nm", f.wavelengths_nm()[size_t(k)]))
                  << (transmission ? fmt::format(", BTDF about the refracted direction, relative index {:.5g}", e.eta)
                                   : std::string(", BRDF"))
                  << ")\n";
        continue;
      }
      MbsdfExport e;
      e.wavelength = k;
      e.colour = rgb ? MbsdfExport::Colour::rgb : MbsdfExport::Colour::scalar;
      const MbsdfFile m = mbsdfFile(f, lookup, e, description);
      writeFileAtomically(path, m.bytes);
      reportMbsdf(path, model, m);
    }
    return 0;
  };
  return c;
}

}  // namespace mbsdf
