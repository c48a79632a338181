// SPDX-License-Identifier: MIT
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "core/error.h"
#include "io/image.h"
#include "support/test_support.h"

using namespace voxlight;

namespace {
// Half float: 11-bit significand, rounding ≤ 2⁻¹¹ ≈ 4.9e-4 relative; plus an absolute floor for the
// ramp's values near 0.
constexpr double kHalfRelTol = 1e-3;
constexpr double kHalfAbsTol = 1e-4;
// RGBE: 8-bit mantissas sharing one exponent, so each channel is within 1/128 of the largest.
constexpr float kRgbeRelTol = 1.0f / 100.0f;
// PNG: one 8-bit quantisation step.
constexpr float kPngStep = 1.0f / 255.0f;
core::ImageRGBA ramp(int w, int h) {
    core::ImageRGBA img(w, h);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            float* p = img.at(x, y);
            p[0] = 0.01f * x + 0.5f, p[1] = 100.0f * y + 0.25f, p[2] = -0.5f + x * y, p[3] = 0.5f;
        }
    return img;
}

int countFiles(const std::filesystem::path& dir) {
    int n = 0;
    for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir)) ++n;
    return n;
}
}  // namespace

TEST(Image, ExrFloatRoundTripIsExact) {
    test::TempDir tmp;
    const auto img = ramp(13, 7);
    io::writeImage(img, tmp / "a.exr");
    io::ImageReadInfo info;
    const auto back = io::readImage(tmp / "a.exr", info);
    EXPECT_TRUE(info.floatingPoint);
    EXPECT_EQ(info.channels, 4);
    ASSERT_EQ(back.width, 13);
    ASSERT_EQ(back.height, 7);
    EXPECT_EQ(back.pixels, img.pixels);
    EXPECT_EQ(countFiles(tmp.path()), 1) << "temporary file left behind";
}

TEST(Image, ExrHalfAndHdrAreWithinTheirPrecision) {
    test::TempDir tmp;
    const auto img = ramp(9, 5);
    io::writeImage(img, tmp / "h.exr", {.exrHalf = true});
    const auto h = io::readImage(tmp / "h.exr");
    for (std::size_t i = 0; i < img.pixels.size(); ++i)
        EXPECT_NEAR(h.pixels[i], img.pixels[i], kHalfRelTol * std::abs(img.pixels[i]) + kHalfAbsTol)
            << i;
    core::ImageRGBA pos = img;
    for (float& v : pos.pixels) v = std::abs(v);
    io::writeImage(pos, tmp / "r.hdr");
    const auto r = io::readImage(tmp / "r.hdr");
    for (int y = 0; y < 5; ++y)
        for (int x = 0; x < 9; ++x)
            for (int c = 0; c < 3; ++c)
                EXPECT_NEAR(
                    r.at(x, y)[c], pos.at(x, y)[c],
                    std::max({pos.at(x, y)[0], pos.at(x, y)[1], pos.at(x, y)[2]}) * kRgbeRelTol);
    EXPECT_EQ(r.at(0, 0)[3], 1.0f);  // alpha promoted
}

TEST(Image, PngClampsAndQuantises) {
    test::TempDir tmp;
    core::ImageRGBA img(4, 1);
    const float values[4] = {-0.5f, 0.5f, 1.7f, 0.25f};
    for (int x = 0; x < 4; ++x) {
        float* p = img.at(x, 0);
        p[0] = p[1] = p[2] = values[x];
        p[3] = 1.0f;
    }
    io::writeImage(img, tmp / "q.png");
    io::ImageReadInfo info;
    const auto back = io::readImage(tmp / "q.png", info);
    EXPECT_FALSE(info.floatingPoint);
    EXPECT_EQ(back.at(0, 0)[0], 0.0f);
    EXPECT_NEAR(back.at(1, 0)[0], 128.0f / 255.0f, kPngStep);
    EXPECT_EQ(back.at(2, 0)[0], 1.0f);
    EXPECT_NEAR(back.at(3, 0)[0], 64.0f / 255.0f, kPngStep);
    img.at(1, 0)[2] = NAN;
    EXPECT_THROW(io::writeImage(img, tmp / "nan.png"), InputError);
    EXPECT_FALSE(std::filesystem::exists(tmp / "nan.png"));
}

TEST(Image, GreyAndGreyAlphaArePromoted) {
    test::TempDir tmp;
    for (int nc : {1, 2}) {
        const auto path = (tmp / ("g" + std::to_string(nc) + ".exr")).string();
        auto out = OIIO::ImageOutput::create(path);
        ASSERT_TRUE(out);
        OIIO::ImageSpec spec(3, 2, nc, OIIO::TypeDesc::FLOAT);
        std::vector<float> data(3 * 2 * nc);
        for (std::size_t i = 0; i < data.size(); ++i) data[i] = float(i) * 0.5f;
        ASSERT_TRUE(out->open(path, spec) && out->write_image(OIIO::TypeDesc::FLOAT, data.data()) &&
                    out->close());
        const auto img = io::readImage(path);
        const float* p = img.at(1, 1);  // pixel index 4
        EXPECT_EQ(p[0], data[4 * nc]);
        EXPECT_EQ(p[1], data[4 * nc]);
        EXPECT_EQ(p[2], data[4 * nc]);
        EXPECT_EQ(p[3], nc == 2 ? data[4 * nc + 1] : 1.0f);
    }
}

TEST(Image, ManyChannelsKeepTheFirstFour) {
    test::TempDir tmp;
    const auto path = (tmp / "layers.exr").string();
    constexpr int kChannels = 7;
    auto out = OIIO::ImageOutput::create(path);
    ASSERT_TRUE(out);
    OIIO::ImageSpec spec(3, 2, kChannels, OIIO::TypeDesc::FLOAT);
    std::vector<float> data(3 * 2 * kChannels);
    for (std::size_t i = 0; i < data.size(); ++i) data[i] = float(i);
    ASSERT_TRUE(out->open(path, spec) && out->write_image(OIIO::TypeDesc::FLOAT, data.data()) &&
                out->close());
    io::ImageReadInfo info;
    const auto img = io::readImage(path, info);
    EXPECT_EQ(info.channels, kChannels);
    for (int p = 0; p < 6; ++p)
        for (int c = 0; c < 4; ++c)
            EXPECT_EQ(img.pixels[4 * p + c], data[p * kChannels + c]) << p << "," << c;
}

// An EXR's colour is its R, G, B (A) or Y channels by name: a renderer's depth channel Z after
// RGB was read as alpha (its NaN background refused as "channel A is NaN"), and a file holding
// only Z compared equal to any grey image of its values.
TEST(Image, ExrChannelsAreChosenByName) {
    test::TempDir tmp;
    auto write = [&](const std::string& name, const std::vector<std::string>& channels) {
        const auto path = (tmp / name).string();
        auto out = OIIO::ImageOutput::create(path);
        OIIO::ImageSpec spec(3, 2, int(channels.size()), OIIO::TypeDesc::FLOAT);
        spec.channelnames = channels;
        std::vector<float> data(3 * 2 * channels.size());
        for (std::size_t i = 0; i < data.size(); ++i)
            data[i] = channels[i % channels.size()] == "Z" ? NAN : float(i);
        EXPECT_TRUE(out->open(path, spec) && out->write_image(OIIO::TypeDesc::FLOAT, data.data()) &&
                    out->close());
        return std::pair{path, data};
    };
    // OpenEXR stores channels sorted by name: B, G, R, Z on disk.
    const auto [rgbz, d] = write("rgbz.exr", {"R", "G", "B", "Z"});
    const auto img = io::readImage(rgbz);
    EXPECT_EQ(img.at(1, 1)[3], 1.0f) << "no alpha channel: opaque";
    const auto [rgba, d4] = write("rgba.exr", {"R", "G", "B", "A"});
    const auto ref = io::readImage(rgba);
    for (int c = 0; c < 3; ++c) EXPECT_EQ(img.at(1, 1)[c], ref.at(1, 1)[c]) << c;
    EXPECT_EQ(ref.at(1, 1)[3], d4[4 * 4 + 3]);
    const auto [zonly, dz] = write("z.exr", {"Z"});
    try {
        io::readImage(zonly);
        ADD_FAILURE() << "a depth-only EXR has no colour";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "channels");
        EXPECT_NE(std::string(e.what()).find("Z"), std::string::npos) << e.what();
    }
}

TEST(Image, BadFilesNameTheFile) {
    test::TempDir tmp;
    try {
        io::readImage(tmp / "nope.exr");
        FAIL();
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("nope.exr"), std::string::npos);
    }
    { std::ofstream(tmp / "junk.exr") << "this is not an image"; }
    EXPECT_THROW(io::readImage(tmp / "junk.exr"), InputError);
    { std::ofstream(tmp / "empty.png"); }
    EXPECT_THROW(io::readImage(tmp / "empty.png"), InputError);
    EXPECT_THROW(io::readImage(tmp.path()), InputError);
    EXPECT_THROW(io::writeImage(core::ImageRGBA{}, tmp / "zero.exr"), InputError);
    EXPECT_THROW(io::writeImage(ramp(2, 2), tmp / "nodir" / "x.exr"), InputError);
    EXPECT_THROW(io::writeImage(ramp(2, 2), tmp / "x.unknownext"), InputError);
}
