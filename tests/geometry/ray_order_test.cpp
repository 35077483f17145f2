// Rays ordered by origin (geometry/ray_order.h): the places are a permutation; along them the
// origins' Morton cells never decrease and rays of one cell keep their given order (a stable sort,
// so the order is unique whatever the threads); coordinates are wrapped into the period; the cells
// grow finer with the number of rays, about 16 rays to a cell.
#include "geometry/ray_order.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

using namespace mbsdf;

namespace {
std::vector<Vec3> randomOrigins(size_t n, double sizeX, double sizeY, double spread, uint32_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-0.5 * spread, 0.5 * spread);
  std::vector<Vec3> o(n);
  for (Vec3& p : o) p = {u(rng) * sizeX, u(rng) * sizeY, u(rng)};
  return o;
}

std::vector<uint32_t> placesOf(const std::vector<Vec3>& o, double sizeX, double sizeY, OriginOrder& order,
                               std::vector<uint32_t>* cellsOut = nullptr) {
  order.prepare(o.size(), sizeX, sizeY);
  std::vector<uint32_t> cells(o.size());
  for (size_t i = 0; i < o.size(); ++i) cells[i] = order.cellOf(o[i]);
  if (cellsOut) *cellsOut = cells;
  const std::span<const uint32_t> p = order.places(cells);
  return {p.begin(), p.end()};
}
}  // namespace

TEST(OriginOrder, StableCountingSortByMortonCell) {
  for (size_t n : {size_t(0), size_t(1), size_t(15), size_t(1000), size_t(70000), size_t(300000)}) {
    // Rays from several periods away (a finite patch's first rays start outside it).
    const std::vector<Vec3> o = randomOrigins(n, 20, 7, 3.0, uint32_t(n));
    OriginOrder order;
    std::vector<uint32_t> cells;
    const std::vector<uint32_t> places = placesOf(o, 20, 7, order, &cells);
    ASSERT_EQ(places.size(), n);
    std::vector<uint32_t> rayAt(n, std::numeric_limits<uint32_t>::max());
    for (size_t i = 0; i < n; ++i) {
      ASSERT_LT(places[i], n);
      ASSERT_EQ(rayAt[places[i]], std::numeric_limits<uint32_t>::max()) << "place taken twice";
      rayAt[places[i]] = uint32_t(i);
      ASSERT_LT(cells[i], order.cellCount());
    }
    for (size_t k = 1; k < n; ++k) {
      const uint32_t a = rayAt[k - 1], b = rayAt[k];
      ASSERT_LE(cells[a], cells[b]) << "place " << k;
      if (cells[a] == cells[b]) {
        ASSERT_LT(a, b) << "rays of one cell out of their order, place " << k;
      }
    }
    // About 16 rays per cell, at most 2^14 cells.
    if (n >= 16 * 4) {
      EXPECT_LE(double(n) / order.cellCount(), 64.0) << n;
    }
    EXPECT_GE(double(std::max<size_t>(n, 1)) / order.cellCount(), n >= 16 ? 16.0 : 0.0) << n;
    EXPECT_LE(order.cellCount(), 1u << 14);
  }
}

TEST(OriginOrder, SameOrderForAnyNumberOfThreads) {
  const std::vector<Vec3> o = randomOrigins(200000, 10, 10, 1.0, 5);
  OriginOrder order;
  std::vector<uint32_t> one, two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = placesOf(o, 10, 10, order);
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = placesOf(o, 10, 10, order);
  }
  EXPECT_EQ(one, two);
}

TEST(OriginOrder, CellsWrapIntoThePeriod) {
  OriginOrder order;
  order.prepare(1 << 20, 20, 10);
  const Vec3 p{3.3, -4.1, 0.2};
  for (int i = -3; i <= 3; ++i)
    for (int j = -2; j <= 2; ++j) EXPECT_EQ(order.cellOf(p + Vec3{20.0 * i, 10.0 * j, 5.0}), order.cellOf(p));
  // Neighbours share a cell, and a point not a number or beyond any period still gets one.
  EXPECT_EQ(order.cellOf({3.3 + 1e-9, -4.1, 0}), order.cellOf(p));
  EXPECT_LT(order.cellOf({std::numeric_limits<double>::quiet_NaN(), 1e300, 0}), order.cellCount());
  // A patch of no extent: one cell.
  order.prepare(1000, 0, 0);
  EXPECT_EQ(order.cellOf(p), 0u);
}
