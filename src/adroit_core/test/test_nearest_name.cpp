#include "adroit_core/nearest_name.h"

#include <gtest/gtest.h>

namespace {

using adroit::didYouMean;
using adroit::editDistance;
using adroit::nearestName;

TEST(EditDistance, CountsInsertionsDeletionsSubstitutionsAndSwaps) {
  EXPECT_EQ(editDistance("", ""), 0u);
  EXPECT_EQ(editDistance("rate", ""), 4u);
  EXPECT_EQ(editDistance("watchdog_timout", "watchdog_timeout"), 1u);
  EXPECT_EQ(editDistance("rtae", "rate"), 1u);  // neighbours swapped
  EXPECT_EQ(editDistance("kitten", "sitting"), 3u);
}

TEST(NearestName, OffersTheClosestPlausibleName) {
  const std::vector<std::string> keys = {"rate", "watchdog_timeout", "lockstep", "scene"};
  EXPECT_EQ(nearestName("watchdog_timout", keys), "watchdog_timeout");
  EXPECT_EQ(nearestName("lokstep", keys), "lockstep");
  EXPECT_EQ(nearestName("completely_different", keys), "");
  EXPECT_EQ(nearestName("x", {}), "");
  EXPECT_EQ(didYouMean("sceen", keys), " (did you mean scene?)");
  EXPECT_EQ(didYouMean("zzzzzzzz", keys), "");
}

}  // namespace
