// SPDX-License-Identifier: MIT
// voxlight compare REFERENCE TEST [--metrics rmse,psnr,ssim,flip,detect] [--map OUT.png] [--json]
// Image metrics of TEST against REFERENCE (analysis/image_metrics.h): one line per metric, or JSON;
// --map writes the per-pixel FLIP error as a magma-coloured image.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "analysis/image_metrics.h"
#include "app/cli_support.h"
#include "app/output_files.h"
#include "io/image.h"

namespace voxlight::app {

namespace {

const std::vector<std::string> kMetricNames = {"rmse", "psnr", "ssim", "flip", "detect"};

std::string sizeText(const core::ImageRGBA& i) {
    return std::to_string(i.width) + "x" + std::to_string(i.height);
}

/// InputError naming `path` and its first NaN or infinite pixel.
void refuseNonFinitePixels(const core::ImageRGBA& image, const std::string& path) {
    for (std::size_t i = 0; i < image.pixels.size(); ++i)
        if (!std::isfinite(image.pixels[i])) {
            const std::size_t p = i / 4;
            const std::string where = "pixel (" + std::to_string(p % std::size_t(image.width)) +
                                      ", " + std::to_string(p / std::size_t(image.width)) +
                                      ") channel " + "RGBA"[i % 4];
            throw InputError(path, "pixels",
                             where + " is " + (std::isnan(image.pixels[i]) ? "NaN" : "infinite"),
                             "compare finite images: re-render it, or repair the pixel");
        }
}

/// JSON has no infinity: an infinite value (PSNR of identical images) is null.
nlohmann::json number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); }

}  // namespace

Command addCompareCommand(CLI::App& app) {
    Command c;
    c.sub = app.add_subcommand("compare",
                               "Image metrics of TEST against REFERENCE (RMSE, PSNR, SSIM, FLIP, "
                               "fraction of pixels with a detectable difference)");
    auto refPath = std::make_shared<std::string>();
    auto testPath = std::make_shared<std::string>();
    auto metrics = std::make_shared<std::vector<std::string>>(kMetricNames);
    auto map = std::make_shared<std::string>();
    auto json = std::make_shared<bool>(false);
    auto ppd = std::make_shared<double>(analysis::FlipOptions{}.pixelsPerDegree);
    auto threshold = std::make_shared<double>(analysis::DetectionOptions{}.threshold);
    auto peak = std::make_shared<double>(1.0);
    auto mask = std::make_shared<std::string>("none");
    c.sub
        ->add_option("REFERENCE", *refPath,
                     "Reference image (PNG/JPEG display-encoded, EXR linear)")
        ->required();
    c.sub->add_option("TEST", *testPath, "Image to compare with it (same size and kind)")
        ->required();
    c.sub
        ->add_option("--metrics", *metrics,
                     "Comma-separated metrics to print (default: all): rmse (and relative RMSE), "
                     "psnr, ssim, flip, detect")
        ->delimiter(',')
        ->check(CLI::IsMember(kMetricNames));
    c.sub->add_option("--map", *map,
                      "Write the per-pixel FLIP error, coloured with magma (0 black .. 1 yellow), "
                      "as a display image (.png, .jpg, .tif, .bmp)");
    c.sub->add_flag("--json", *json, "Print JSON instead of text");
    c.sub->add_option("--ppd", *ppd, "FLIP: pixels per degree of visual angle")
        ->check(finiteNumber())
        ->check(CLI::Range(1.0, 1000.0));
    c.sub
        ->add_option("--threshold", *threshold,
                     "detect: FLIP value above which a pixel's difference counts as detected")
        ->check(finiteNumber())
        ->check(CLI::Range(0.0, 0.999));
    // Bounded: a peak near DBL_MAX squared to ∞ (psnr "inf dB"), and CLI::PositiveNumber's
    // message printed DBL_MAX in 309 digits.
    c.sub->add_option("--peak", *peak, "PSNR's peak value (1 for 0..1 images)")
        ->check(CLI::Validator(
            [](std::string& text) -> std::string {
                double v = 0.0;
                try {
                    v = std::stod(text);
                } catch (const std::exception&) {
                    return "'" + text + "' is not a number";
                }
                return v >= 1e-12 && v <= 1e12 ? std::string()
                                               : "'" + text + "' is not in [1e-12, 1e12]";
            },
            "PEAK"));
    c.sub
        ->add_option("--mask", *mask,
                     "Pixels averaged: all (none), or those covered in either image's alpha "
                     "(either way a PNG "
                     "with alpha is compared as seen over black: colours times alpha)")
        ->check(CLI::IsMember({"none", "alpha"}));
    c.run = [=] {
        checkOutputs({{"--map", *map, {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp"}}},
                     {{"REFERENCE", *refPath}, {"TEST", *testPath}});
        io::ImageReadInfo refInfo, testInfo;
        const core::ImageRGBA ref = io::readImage(*refPath, refInfo);
        const core::ImageRGBA test = io::readImage(*testPath, testInfo);
        // A NaN or Inf pixel (an EXR from a broken render) made RMSE/PSNR nan or inf while SSIM
        // and FLIP, on the clamped display values, still read "identical".
        refuseNonFinitePixels(ref, *refPath);
        refuseNonFinitePixels(test, *testPath);
        if (ref.width != test.width || ref.height != test.height)
            throw InputError("command line", "TEST",
                             *refPath + " is " + sizeText(ref) + " pixels but " + *testPath +
                                 " is " + sizeText(test),
                             "compare images of the same size");
        if (refInfo.floatingPoint != testInfo.floatingPoint)
            throw InputError("command line", "TEST",
                             *refPath + " is " +
                                 (refInfo.floatingPoint ? "linear (HDR)" : "display-encoded") +
                                 " but " + *testPath + " is " +
                                 (testInfo.floatingPoint ? "linear (HDR)" : "display-encoded"),
                             "compare two PNGs or two EXRs (render writes both: -o and --exr)");
        analysis::MetricOptions o;
        o.encoding =
            refInfo.floatingPoint ? analysis::Encoding::Linear : analysis::Encoding::Display;
        if (*mask == "alpha") {
            o.mask = analysis::coverageMask(ref, test);
            if (std::none_of(o.mask.begin(), o.mask.end(), [](auto m) { return m != 0; }))
                throw InputError("command line", "--mask", "no pixel has alpha > 0 in either image",
                                 "use --mask none for images without coverage in alpha");
        }
        auto wants = [&](const std::string& m) {
            return std::find(metrics->begin(), metrics->end(), m) != metrics->end();
        };

        nlohmann::json j;
        j["reference"] = *refPath;
        j["test"] = *testPath;
        j["width"] = ref.width;
        j["height"] = ref.height;
        j["encoding"] = refInfo.floatingPoint ? "linear" : "display";
        j["mask"] = *mask;
        std::vector<std::string> lines;
        char b[256];
        if (wants("rmse") || wants("psnr")) {
            const analysis::ErrorStats e = analysis::errorStats(ref, test, o, *peak);
            j["pixels"] = e.pixels;
            if (wants("rmse")) {
                j["rmse"] = e.rmse;
                j["nrmse"] = number(e.nrmse);
                std::snprintf(b, sizeof b, "rmse:   %.6g (relative %.6g)", e.rmse, e.nrmse);
                lines.push_back(b);
            }
            if (wants("psnr")) {
                j["psnr_db"] = number(e.psnrDb);
                j["psnr_peak"] = e.peak;
                std::snprintf(b, sizeof b, "psnr:   %.4g dB (peak %g)", e.psnrDb, e.peak);
                lines.push_back(b);
            }
        }
        if (wants("ssim")) {
            j["ssim"] = analysis::ssim(ref, test, o).mean;
            std::snprintf(b, sizeof b, "ssim:   %.6f", j["ssim"].get<double>());
            lines.push_back(b);
        }
        analysis::FlipResult f;
        const bool needFlip = wants("flip") || wants("detect") || !map->empty();
        if (needFlip) f = analysis::flip(ref, test, o, {.pixelsPerDegree = *ppd});
        if (wants("flip")) {
            j["flip"] = f.mean;
            j["flip_ppd"] = *ppd;
            std::snprintf(b, sizeof b, "flip:   %.6f (%g pixels per degree)", f.mean, *ppd);
            lines.push_back(b);
        }
        if (wants("detect")) {
            j["detect"] = analysis::detectionFraction(f.map, o, {.threshold = *threshold});
            j["detect_threshold"] = *threshold;
            std::snprintf(b, sizeof b, "detect: %.6f of pixels with FLIP > %g",
                          j["detect"].get<double>(), *threshold);
            lines.push_back(b);
        }
        if (!map->empty()) {
            const core::ImageRGBA colours = analysis::errorMap(f.map);
            OutputFiles files;
            throwIfCancelled();
            files.write(*map, "--map",
                        [&](const std::filesystem::path& p) { io::writeImage(colours, p); });
            throwIfCancelled();
            files.commit();
            j["map"] = *map;
        }
        if (*json) {
            std::cout << j.dump(2) << "\n";
        } else {
            for (const auto& l : lines) std::printf("%s\n", l.c_str());
        }
        return kExitOk;
    };
    return c;
}

}  // namespace voxlight::app
