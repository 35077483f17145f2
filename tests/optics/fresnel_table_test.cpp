// The tabulated conductor reflectance against the exact formula, as sweeps over cos θ (grazing
// included) for every built-in conductor across the visible.
#include "optics/fresnel_table.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "optics/material.h"

using namespace mbsdf;

TEST(ConductorFresnelTable, WithinOneMillionthOfTheExactReflectanceOverTheVisible) {
  int conductors = 0;
  for (const std::string& name : builtinMaterialNames()) {
    Material m;
    ASSERT_TRUE(builtinMaterial(name, &m));
    if (!m.isConductor() || m.isPerfectConductor()) continue;
    ++conductors;
    for (double lambda_um = 0.38; lambda_um <= 0.78 + 1e-9; lambda_um += 0.02) {
      const Complex n2 = m.ior(lambda_um);
      const ConductorFresnelTable table(m.outsideIor, n2);
      double worst = 0;
      // Off the nodes (where the interpolation error is largest) and on them, grazing to normal.
      const int n = 20011;
      for (int i = 0; i <= n; ++i) {
        const double cosTheta = double(i) / n;
        worst = std::max(worst, std::abs(table(cosTheta) - fresnelReflectance(cosTheta, m.outsideIor, n2)));
      }
      EXPECT_LT(worst, 1e-6) << name << " at " << lambda_um << " µm";
      EXPECT_EQ(table(1.0), fresnelReflectance(1.0, m.outsideIor, n2)) << name;
      EXPECT_EQ(table(0.0), fresnelReflectance(0.0, m.outsideIor, n2)) << name;
    }
  }
  EXPECT_GE(conductors, 4);
}

// Out of [0, 1] (rounding, or a NaN from upstream) the index stays inside the table.
TEST(ConductorFresnelTable, ClampsItsArgument) {
  Material al;
  ASSERT_TRUE(builtinMaterial("Al", &al));
  const ConductorFresnelTable table(al.outsideIor, al.ior(0.55));
  EXPECT_EQ(table(1.0 + 1e-12), table(1.0));
  EXPECT_EQ(table(-1e-12), table(0.0));
  EXPECT_EQ(table(std::nan("")), table(0.0));
  EXPECT_EQ(table(std::numeric_limits<double>::infinity()), table(1.0));
}
