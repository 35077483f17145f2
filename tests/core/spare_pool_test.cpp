// The spare pool: an empty pool gives a default object; what is given back is what the next take
// gets, storage included; a lease gives its object back when it ends, also through an exception.
#include "core/spare_pool.h"

#include <gtest/gtest.h>

#include <stdexcept>
#include <vector>

namespace mbsdf {
namespace {

TEST(SparePool, GivesBackWhatWasGivenWithItsStorage) {
  SparePool<std::vector<int>> pool;
  EXPECT_TRUE(pool.take().empty());
  std::vector<int> v(1000, 7);
  const int* storage = v.data();
  pool.giveBack(std::move(v));
  const std::vector<int> again = pool.take();
  EXPECT_EQ(again.data(), storage);
  EXPECT_EQ(again.size(), 1000u);
  EXPECT_TRUE(pool.take().empty());
}

TEST(SparePool, ALeaseGivesItsObjectBackAlsoThroughAnException) {
  SparePool<std::vector<int>> pool;
  const int* storage = nullptr;
  try {
    SparePool<std::vector<int>>::Lease lease(pool);
    lease->assign(50, 1);
    storage = lease->data();
    throw std::runtime_error("abandoned");
  } catch (const std::runtime_error&) {
  }
  SparePool<std::vector<int>>::Lease again(pool);
  EXPECT_EQ(again->data(), storage);
  EXPECT_EQ((*again).size(), 50u);
}

}  // namespace
}  // namespace mbsdf
