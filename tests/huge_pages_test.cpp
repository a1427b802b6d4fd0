// The advice that asks for 2 MiB pages behind large arrays (tree/huge_pages.h) changes where
// memory comes from, never what it holds: a vector keeps its elements and gets its room,
// arrays that already have their room are left alone, and advice on any
// range (unaligned, empty, inside a buffer) leaves the bytes as they were. Whether the
// system grants huge pages is its own choice; bench/ measures what it is worth.
#include <gtest/gtest.h>

#include <cstdint>
#include <numeric>
#include <vector>

#include "tree/huge_pages.h"

namespace bvhopt {
namespace {

TEST(HugePages, ReserveKeepsTheElementsAndMakesRoom) {
  std::vector<uint32_t> v = {1, 2, 3};
  constexpr size_t kCount = size_t(3) << 20;  // 12 MiB: several whole huge pages
  detail::reserve_on_huge_pages(v, kCount);
  EXPECT_GE(v.capacity(), kCount);
  EXPECT_EQ(v, (std::vector<uint32_t>{1, 2, 3}));
  const uint32_t* room = v.data();
  v.resize(kCount, 7u);
  EXPECT_EQ(v.data(), room);  // filled in the room reserved, not elsewhere
  EXPECT_EQ(v[2], 3u);
  EXPECT_EQ(v[3], 7u);
  EXPECT_EQ(v.back(), 7u);
}

TEST(HugePages, SmallVectorsGetTheirRoomAndRoomyOnesAreLeftAlone) {
  std::vector<uint32_t> small = {9};
  detail::reserve_on_huge_pages(small, 1000);  // 4 KB: under one huge page, reserved as ever
  EXPECT_GE(small.capacity(), 1000u);
  EXPECT_EQ(small, std::vector<uint32_t>{9});
  std::vector<uint32_t> roomy;
  roomy.reserve(size_t(4) << 20);
  roomy.push_back(5);
  const uint32_t* before = roomy.data();
  detail::reserve_on_huge_pages(roomy, size_t(1) << 20);
  EXPECT_EQ(roomy.data(), before);
  EXPECT_EQ(roomy.size(), 1u);
  EXPECT_EQ(roomy[0], 5u);
}

TEST(HugePages, AdviceOnAnyRangeKeepsTheBytes) {
  std::vector<uint8_t> buffer(size_t(5) << 20);
  std::iota(buffer.begin(), buffer.end(), uint8_t{0});
  for (size_t offset : {size_t(0), size_t(1), size_t(4095), size_t(1) << 20})
    for (size_t bytes : {size_t(0), size_t(1), size_t(2) << 20, (size_t(3) << 20) + 17})
      detail::advise_huge_pages(buffer.data() + offset, bytes);
  for (size_t i = 0; i < buffer.size(); ++i)
    if (buffer[i] != static_cast<uint8_t>(i)) FAIL() << "byte " << i << " changed";
}

}  // namespace
}  // namespace bvhopt
