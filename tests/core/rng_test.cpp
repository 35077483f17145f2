#include "core/rng.h"

#include <gtest/gtest.h>

#include <vector>

using namespace mbsdf;

// A sampler resumed from the position of another (same seed, tile, sample, stream) draws the very
// numbers the other draws next: after any count of draws (odd counts leave the second number of a
// block pending) and after a jump to a dimension.
TEST(Sampler, ResumesWhereAnotherStood) {
  for (int drawn = 0; drawn < 9; ++drawn) {
    for (bool jump : {false, true}) {
      Sampler a(11, 3, 123456789012ull, 2);
      if (jump) a.setDimension(40);
      for (int i = 0; i < drawn; ++i) a.get1D();
      Sampler b(11, 3, 123456789012ull, 2);
      b.get1D();  // wherever it stands before, resume puts it at a's position
      b.resume(a.nextBlock(), a.secondLeft());
      EXPECT_EQ(b.nextBlock(), a.nextBlock());
      EXPECT_EQ(b.secondLeft(), a.secondLeft());
      for (int i = 0; i < 7; ++i) ASSERT_EQ(b.get1D(), a.get1D()) << drawn << " drawn, jump " << jump << ", draw " << i;
    }
  }
}

// The position is all that differs between samplers of one path: another sample or stream at the
// same position draws other numbers.
TEST(Sampler, ResumedNumbersBelongToTheirPath) {
  Sampler a(11, 3, 5, 0);
  a.get1D();
  Sampler other(11, 3, 6, 0);
  other.resume(a.nextBlock(), a.secondLeft());
  EXPECT_NE(other.get1D(), a.get1D());
}
