// A tabulated BSDF from an output file as the preview's material: f between bins and incidences by
// the one interpolation every reader of a table uses (io/bsdf_lookup.h), a table's rows turned into
// linear sRGB (CIE 1931 through the file's wavelengths or colour channels; grey when no wavelength
// is visible).
//
// Sampling draws wi from the slice the lookup weighs most for the viewer's direction wo used as the
// incidence (reciprocity, f(wi → wo) = f(wo → wi) for reflection): an exit bin with probability
// ∝ mean(f_b) Ω⊥_b, then a point about its centre with a tent density in the grid's continuous
// coordinates (θ, φ on a theta-phi grid, x, y on the disk), the shape of the bilinear interpolation
// itself, so that a lobe one bin wide is sampled in proportion to what eval returns. A tenth of the
// draws (all, for a slice without light) are cosine-weighted on each side in proportion to the slice's
// energy there, so that every direction eval can return is sampled.
//
// A table whose incidences are a list without a rule between them (BsdfLookup::nearestOnly: an
// anisotropic surface at a few incidences) is read from the viewer's side, f(wi → wo) = f(wo → wi)
// (η_o/η_i)² from the slice nearest to wo: what a point sends to the viewer is then bounded by that
// slice's albedo, as energy requires, and drawn exactly as eval weighs it. Read from the light's side,
// one slice would stand for every light direction of its region, and a sharp lobe (a grating's order)
// would return its peak over that whole region: a point brighter than the light (5× in a test). A
// viewer on a side such a list has no incidence on (inside a glass object, for a list from above)
// has to be lit through the light's slice after all, and `lightSliceInside` says so.
//
// A partial file (a run still going, or stopped): where the rule between incidences needs a slice that
// is not finished, the nearest finished incidence on the same side stands in, and
// `unfinishedReplaced` says so.
//
// Light from a side the table holds no incidence on (light inside a closed object, for a table
// computed from above only) is evaluated by reciprocity, f(wi → wo) = f(wo → wi) (η_o/η_i)², with η_o
// and η_i the indices of the media wo and wi lie in (Veach 1997, Eq. 5.14): the factor matters for
// transmission only and needs the index below the surface relative to above (insideIor, the mean
// over the table's wavelengths); when it is not known (0) the factor is left out and
// `etaFactorMissing` says so.
#pragma once
#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "io/bsdf_lookup.h"
#include "render/render_material.h"

namespace mbsdf {

class TabulatedMaterial : public RenderMaterial {
 public:
  // InputError when the file lacks the model's components or holds no finished slice.
  TabulatedMaterial(const BsdfFileReader& file, const std::string& model, double insideIor = 0);
  Colour3 eval(const Vec3& wi, const Vec3& wo) const override;
  std::optional<MaterialSample> sample(const Vec3& wo, Sampler& s) const override;
  double pdf(const Vec3& wo, const Vec3& wi) const override;
  // Whether eval used reciprocity for a side without incidences, and whether for light through the
  // surface without its factor (see above).
  bool reciprocityUsed() const { return reciprocityUsed_.load(); }
  bool etaFactorMissing() const { return etaFactorMissing_.load(); }
  bool lightSliceInside() const { return lightSliceInside_.load(); }
  bool unfinishedReplaced() const { return unfinishedReplaced_.load(); }
  const BsdfLookup& lookup() const { return lookup_; }

 private:
  struct Slice {
    std::vector<float> rgb;    // 3 × nBins
    std::vector<double> prob;  // per bin: mean(f_b) Ω⊥_b normalised
    std::vector<double> cdf;   // nBins + 1
    double upperShare = 0.5;   // of the slice's energy, above the surface
    bool empty = true;
  };
  const Slice& slice(int incidence) const;
  Colour3 evalAt(int incidence, const Vec3& wo) const;  // bilinear between bins
  Colour3 evalFrom(const Vec3& wi, const Vec3& wo) const;
  // The slice sampling draws from for the viewer at wo and the turn onto it; no slice when the table
  // holds none on wo's side.
  struct Drawn {
    const Slice* slice = nullptr;
    double turn = 0;
    bool fromTable() const { return slice && !slice->empty; }
    double upperShare() const { return fromTable() ? slice->upperShare : 0.5; }
  };
  Drawn drawnFrom(const Vec3& wo) const;
  double pdfIn(const Drawn& d, const Vec3& wi) const;  // pdf(wo, wi) for d = drawnFrom(wo)
  // `incidence` when finished, else the finished one nearest to it on its side.
  int finished(int incidence) const;
  double tentPdf(const Slice& s, const Vec3& w) const;

  const BsdfFileReader& file_;
  BsdfLookup lookup_;
  std::vector<Colour3> toRgb_;  // per row
  mutable std::vector<std::unique_ptr<Slice>> slices_;
  std::unique_ptr<std::once_flag[]> once_;
  mutable std::mutex fileMutex_;  // HDF5 reads one at a time
  double insideIor_ = 0;
  mutable std::atomic<bool> reciprocityUsed_{false}, etaFactorMissing_{false}, lightSliceInside_{false};
  mutable std::atomic<bool> unfinishedReplaced_{false};
  std::vector<int> nearestFinished_;  // per incidence
  bool finishedAbove_ = false, finishedBelow_ = false;
  // Whether a finished slice has its incidence above (below) the surface.
  bool holds(bool above) const { return above ? finishedAbove_ : finishedBelow_; }
};

}  // namespace mbsdf
