#include "optics/fresnel_table.h"

namespace mbsdf {

ConductorFresnelTable::ConductorFresnelTable(double n1, Complex n2) : f_(size_t(kIntervals) + 1) {
  for (int i = 0; i <= kIntervals; ++i) f_[size_t(i)] = fresnelReflectance(double(i) / kIntervals, n1, n2);
}

std::vector<ConductorFresnelTable> conductorFresnelTables(const Material& material, const std::vector<Complex>& ior) {
  std::vector<ConductorFresnelTable> tables;
  if (material.isConductor() && !material.isPerfectConductor())
    for (const Complex& n2 : ior) tables.emplace_back(material.outsideIor, n2);
  return tables;
}

}  // namespace mbsdf
