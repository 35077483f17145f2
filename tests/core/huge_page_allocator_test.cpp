// The huge-page allocator (core/huge_page_allocator.h): buffers start on a 2 MB boundary, hold what
// is written to them, grow and shrink as std::vector's, and give their memory back.
#include "core/huge_page_allocator.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <numeric>
#include <vector>

using namespace mbsdf;

TEST(HugePageAllocator, AlignedBuffersThatHoldTheirValues) {
  for (size_t n : {size_t(1), size_t(1000), size_t(300000), size_t(5000000)}) {
    std::vector<uint64_t, HugePageAllocator<uint64_t>> v(n);
    EXPECT_EQ(reinterpret_cast<uintptr_t>(v.data()) % HugePageAllocator<uint64_t>::kHugePage, 0u) << n;
    EXPECT_EQ(std::accumulate(v.begin(), v.end(), uint64_t(0)), 0u) << "value-initialised";
    std::iota(v.begin(), v.end(), uint64_t(1));
    v.resize(n + 12345);  // moves to a larger buffer
    for (size_t i = 0; i < n; i += n / 7 + 1) ASSERT_EQ(v[i], i + 1);
    EXPECT_EQ(v[n + 12344], 0u);
  }
  // Many buffers allocated and freed in turn: the mappings are released (no exhaustion).
  for (int k = 0; k < 2000; ++k) {
    std::vector<double, HugePageAllocator<double>> w(size_t(1) << 18, 1.0);
    ASSERT_EQ(w.back(), 1.0);
  }
}
