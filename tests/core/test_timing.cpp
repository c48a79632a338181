// SPDX-License-Identifier: MIT
// The progress line's times: durations for people, and the time left at the rate so far.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "core/timing.h"

using voxlight::core::durationText;
using voxlight::core::kEstimateFraction;
using voxlight::core::progressTimes;

TEST(Timing, DurationsReadAsSecondsThenMinutesThenHours) {
    EXPECT_EQ(durationText(0.0), "0 s");
    EXPECT_EQ(durationText(0.4), "0 s");
    EXPECT_EQ(durationText(42.4), "42 s");
    EXPECT_EQ(durationText(59.4), "59 s");
    EXPECT_EQ(durationText(59.6), "1 min 00 s");
    EXPECT_EQ(durationText(185.0), "3 min 05 s");
    EXPECT_EQ(durationText(3599.0), "59 min 59 s");
    EXPECT_EQ(durationText(3600.0), "1 h 00 min");
    EXPECT_EQ(durationText(2 * 3600.0 + 7 * 60 + 59), "2 h 07 min");
}

TEST(Timing, ADurationThatIsNoTimeOrTooLongStaysReadable) {
    EXPECT_EQ(durationText(-5.0), "0 s");
    EXPECT_EQ(durationText(std::numeric_limits<double>::quiet_NaN()), "0 s");
    // 10⁹ s is the cap: 277777 h 46 min.
    EXPECT_EQ(durationText(1e300), "277777 h 46 min");
    EXPECT_EQ(durationText(std::numeric_limits<double>::infinity()), "277777 h 46 min");
}

TEST(Timing, TheTimeLeftIsTheRateSoFarOverWhatRemains) {
    EXPECT_EQ(progressTimes(12.0, 0.25), "12 s, ≈ 36 s left");
    EXPECT_EQ(progressTimes(20.0, 0.01), "20 s, ≈ 33 min 00 s left");  // pvrt's photons at 1e5
    EXPECT_EQ(progressTimes(30.0, 0.5), "30 s, ≈ 30 s left");
}

TEST(Timing, NoEstimateBeforeTheFirstPercentOrAtTheEnd) {
    EXPECT_EQ(progressTimes(5.0, 0.0), "5 s");
    EXPECT_EQ(progressTimes(5.0, kEstimateFraction * 0.99), "5 s");
    EXPECT_EQ(progressTimes(5.0, 1.0), "5 s");
    EXPECT_EQ(progressTimes(5.0, 1.5), "5 s");
    EXPECT_EQ(progressTimes(5.0, std::nan("")), "5 s");
}
