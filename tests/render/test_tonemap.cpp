// SPDX-License-Identifier: MIT
// Display transforms (render/tonemap.h): exact values at the anchors, monotone, bounded, and
// non-finite radiance never reaching the display as anything but black.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"
#include "render/tonemap.h"

using namespace voxlight;
using render::Display;

namespace {
core::ImageRGBA film(std::initializer_list<float> values) {
    core::ImageRGBA im(int(values.size()), 1);
    int i = 0;
    for (float v : values) {
        float* p = im.at(i++, 0);
        p[0] = p[1] = p[2] = v;
        p[3] = 0.5f;
    }
    return im;
}
}  // namespace

TEST(Tonemap, ClinicalMapsTheCompositedValueStraightToTheDisplay) {
    const auto out = render::toDisplay(film({0.f, 0.25f, 0.5f, 1.f, 3.f}), 0.f, Display::Clinical);
    const float expected[] = {0.f, 0.25f, 0.5f, 1.f, 1.f};
    for (int i = 0; i < 5; ++i) EXPECT_EQ(out.at(i, 0)[0], expected[i]) << i;
    EXPECT_EQ(out.at(0, 0)[3], 1.f) << "opaque: the film's RGB already holds the background";
    // Exposure is a power of two on the radiance.
    EXPECT_EQ(render::toDisplay(film({0.25f}), 1.f, Display::Clinical).at(0, 0)[0], 0.5f);
}

TEST(Tonemap, SrgbIsTheStandardCurve) {
    EXPECT_EQ(render::linearToSrgb(0.f), 0.f);
    EXPECT_EQ(render::linearToSrgb(1.f), 1.f);
    EXPECT_NEAR(render::linearToSrgb(0.5f), 0.735357f, 1e-5f);  // IEC 61966-2-1
    EXPECT_NEAR(render::srgbToLinear(render::linearToSrgb(0.2f)), 0.2f, 1e-6f);
    EXPECT_NEAR(render::toDisplay(film({0.5f}), 0.f, Display::Srgb).at(0, 0)[0], 0.735357f, 1e-5f);
}

TEST(Tonemap, FilmicRollsOffHighlightsMonotonically) {
    EXPECT_EQ(render::acesFilmic(0.f), 0.f);
    // Strictly increasing below its white point (Narkowicz's fit tends to 2.51/2.43 > 1, so it
    // reaches white near 7.9, three stops above 1), flat at 1 beyond.
    float previous = 0.f;
    for (float x = 0.01f; x < 100.f; x *= 1.1f) {
        const float y = render::acesFilmic(x);
        if (x < 7.5f) {
            EXPECT_GT(y, previous) << x;
            EXPECT_LT(y, 1.f) << x;
        } else {
            EXPECT_GE(y, previous) << x;
            EXPECT_LE(y, 1.f) << x;
        }
        previous = y;
    }
    EXPECT_EQ(render::acesFilmic(100.f), 1.f);
    // Radiance 4 (two stops over white) is still below white: no clipping of highlights.
    EXPECT_LT(render::toDisplay(film({4.f}), 0.f, Display::Filmic).at(0, 0)[0], 1.f);
    EXPECT_EQ(render::acesFilmic(std::numeric_limits<float>::infinity()), 1.f);
}

TEST(Tonemap, NonFiniteRadianceIsBlackInEveryMode) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (Display d : {Display::Clinical, Display::Srgb, Display::Filmic}) {
        const auto out = render::toDisplay(film({nan, -1.f}), 0.f, d);
        EXPECT_EQ(out.at(0, 0)[0], 0.f);
        EXPECT_EQ(out.at(1, 0)[0], 0.f);
    }
}

TEST(Tonemap, UnknownDisplayNamesAreAnInputErrorListingTheChoices) {
    EXPECT_EQ(render::displayFromString("filmic"), Display::Filmic);
    try {
        render::displayFromString("aces");
        FAIL();
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("clinical, srgb, filmic"), std::string::npos);
    }
}

TEST(Tonemap, ClippingCountsWhitePixelsOfWhatShowsAndTheExposureThatFitsThem) {
    // Five pixels at alpha 0.5, one more that shows nothing (alpha 0, a NaN radiance).
    core::ImageRGBA im = film({2.f, 2.f, 2.f, 0.5f, 0.999f});
    core::ImageRGBA withHidden(6, 1);
    for (int i = 0; i < 5; ++i) std::copy_n(im.at(i, 0), 4, withHidden.at(i, 0));
    withHidden.at(5, 0)[0] = std::numeric_limits<float>::quiet_NaN();
    constexpr float kMinAlpha = 0.5f / 255.f;
    const auto c = render::displayClipping(withHidden, 0.f, Display::Clinical, kMinAlpha);
    EXPECT_EQ(c.shown, 5u);
    EXPECT_EQ(c.white, 4u) << "0.999 rounds to 255 (from 254.5/255 = 0.99804), 0.5 does not";
    // The 95th percentile's largest channel, 2, reaches white (0.998) at log2(0.998/2) = −1.003
    // stops, rounded down to a tenth: −1.1.
    EXPECT_FLOAT_EQ(c.exposureToFit, -1.1f);
    // Exposure applies first, and one channel under white keeps a pixel from counting.
    EXPECT_EQ(render::displayClipping(withHidden, -1.1f, Display::Clinical, kMinAlpha).white, 0u);
    im.at(0, 0)[2] = 0.9f;
    EXPECT_EQ(render::displayClipping(im, 0.f, Display::Clinical, kMinAlpha).white, 3u);
    // Filmic reaches white only near 7.9 (three stops up): 2 is not white there.
    const auto f = render::displayClipping(withHidden, 0.f, Display::Filmic, kMinAlpha);
    EXPECT_EQ(f.white, 0u);
    EXPECT_GT(f.exposureToFit, 1.5f);
    EXPECT_EQ(render::displayClipping(withHidden, 3.f, Display::Filmic, kMinAlpha).white, 4u)
        << "16 and 7.99 past its white point, 4 not";
    // Nothing shows: nothing white, the exposure as given.
    const auto none = render::displayClipping(withHidden, 0.7f, Display::Srgb, 1.f);
    EXPECT_EQ(none.shown, 0u);
    EXPECT_FLOAT_EQ(none.exposureToFit, 0.7f);
}
