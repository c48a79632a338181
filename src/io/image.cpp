// SPDX-License-Identifier: MIT
// OpenImageIO stays inside this translation unit (no GDCM/VTK includes here: their headers clash,
// BUILD-NOTES).
#include "io/image.h"

#include <OpenImageIO/imageio.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <string>
#include <system_error>

#include "core/error.h"

namespace voxlight::io {

namespace {
std::string lowerExtension(const std::filesystem::path& p) {
    std::string e = p.extension().string();
    std::transform(e.begin(), e.end(), e.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return e;
}

std::string oiioError(const std::string& fromObject) {
    std::string e = fromObject.empty() ? OIIO::geterror() : fromObject;
    while (!e.empty() && (e.back() == '\n' || e.back() == ' ')) e.pop_back();
    return e.empty() ? "unknown OpenImageIO error" : e;
}
}  // namespace

ImageRGBA readImage(const std::filesystem::path& path) {
    ImageReadInfo info;
    return readImage(path, info);
}

ImageRGBA readImage(const std::filesystem::path& path, ImageReadInfo& info) {
    const std::string file = path.string();
    std::error_code ec;
    if (!std::filesystem::exists(path, ec))
        throw InputError(file, "file", "image file does not exist", "check the path");
    if (std::filesystem::is_directory(path, ec))
        throw InputError(file, "file", "is a directory, not an image file",
                         "give the path of an image file");
    auto in = OIIO::ImageInput::open(file);
    if (!in)
        throw InputError(
            file, "file", "cannot be read as an image: " + oiioError({}),
            "give a valid .hdr, .exr, .png or .jpg file (is it truncated or mislabelled?)");
    const OIIO::ImageSpec& spec = in->spec();
    info.channels = spec.nchannels;
    info.floatingPoint = spec.format.is_floating_point();
    info.format = in->format_name();
    const int w = spec.width, h = spec.height, nc = spec.nchannels;
    if (w <= 0 || h <= 0 || nc <= 0)
        throw InputError(file, "size",
                         "image has zero size (" + std::to_string(w) + "×" + std::to_string(h) +
                             ", " + std::to_string(nc) + " channels)",
                         "give a non-empty image");
    if (std::uint64_t(w) * std::uint64_t(h) > (std::uint64_t(1) << 28))
        throw InputError(file, "size",
                         "image is " + std::to_string(w) + "×" + std::to_string(h) +
                             ", larger than the 2^28-pixel limit",
                         "downsample the image");
    // Only the channels used below are decoded: a many-channel EXR (AOVs, layers) would otherwise
    // allocate nc floats per pixel, up to 2^28 · nc.
    const int used = std::min(nc, 4);
    std::vector<float> raw(std::size_t(w) * h * used);
    if (!in->read_image(0, 0, 0, used, OIIO::TypeDesc::FLOAT, raw.data()))
        throw InputError(file, "pixels",
                         "pixel data cannot be decoded: " + oiioError(in->geterror()),
                         "the file is probably truncated or corrupt; re-export it");
    in->close();

    ImageRGBA img(w, h);
    for (std::size_t p = 0; p < std::size_t(w) * h; ++p) {
        const float* s = &raw[p * used];
        float* d = &img.pixels[p * 4];
        if (nc <= 2) {
            d[0] = d[1] = d[2] = s[0];
            d[3] = nc == 2 ? s[1] : 1.0f;
        } else {
            d[0] = s[0], d[1] = s[1], d[2] = s[2];
            d[3] = nc >= 4 ? s[3] : 1.0f;
        }
    }
    return img;
}

void writeImage(const ImageRGBA& image, const std::filesystem::path& path) {
    writeImage(image, path, ImageWriteOptions{});
}

void writeImage(const ImageRGBA& image, const std::filesystem::path& path,
                const ImageWriteOptions& options) {
    const std::string file = path.string();
    const int w = image.width, h = image.height;
    if (w <= 0 || h <= 0 || image.pixels.size() != std::size_t(4) * w * h)
        throw InputError(file, "image",
                         "cannot write an image of " + std::to_string(w) + "×" + std::to_string(h) +
                             " with " + std::to_string(image.pixels.size()) + " floats",
                         "the image must be non-empty with 4·width·height values");
    const std::string ext = lowerExtension(path);
    const bool hdr = ext == ".hdr", exr = ext == ".exr";
    const bool eightBit = !hdr && !exr && ext != ".pfm" && ext != ".tif" && ext != ".tiff";

    int channels = hdr ? 3 : 4;
    OIIO::TypeDesc type = OIIO::TypeDesc::FLOAT;
    if (exr && options.exrHalf) type = OIIO::TypeDesc::HALF;
    if (eightBit) type = OIIO::TypeDesc::UINT8;
    if (ext == ".jpg" || ext == ".jpeg") channels = 3;

    // Pixels to write, as float; 8-bit formats are clamped to 0..1 (OIIO rounds), non-finite values
    // rejected.
    std::vector<float> data(std::size_t(w) * h * channels);
    for (std::size_t p = 0; p < std::size_t(w) * h; ++p) {
        for (int c = 0; c < channels; ++c) {
            float v = image.pixels[p * 4 + c];
            if (eightBit) {
                if (!std::isfinite(v))
                    throw InputError(file, "pixels",
                                     "pixel (" + std::to_string(p % w) + ", " +
                                         std::to_string(p / w) + ") channel " + std::to_string(c) +
                                         " is not finite",
                                     "fix the NaN/Inf upstream, or write .exr to keep them");
                v = std::clamp(v, 0.0f, 1.0f);
            }
            data[p * channels + c] = v;
        }
    }

    // Temporary name in the same directory, same extension (OpenImageIO picks the format from it).
    static std::atomic<int> counter{0};
    const std::filesystem::path dir =
        path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
    const std::filesystem::path tmp =
        dir / (path.stem().string() + ".tmp" + std::to_string(::getpid()) + "_" +
               std::to_string(counter++) + path.extension().string());
    auto out = OIIO::ImageOutput::create(tmp.string());
    if (!out)
        throw InputError(file, "extension", "no image writer for \"" + ext + "\": " + oiioError({}),
                         "use .exr (linear HDR), .hdr or .png");
    OIIO::ImageSpec spec(w, h, channels, type);
    if (exr) spec.attribute("compression", "zip");
    if (!out->open(tmp.string(), spec) || !out->write_image(OIIO::TypeDesc::FLOAT, data.data()) ||
        !out->close()) {
        const std::string err = oiioError(out->geterror());
        std::error_code ec;
        std::filesystem::remove(tmp, ec);
        throw InputError(file, "file", "cannot write image: " + err,
                         "check that the directory exists and is writable");
    }
    std::error_code ec;
    std::filesystem::rename(tmp, path, ec);
    if (ec) {
        std::filesystem::remove(tmp, ec);
        throw InputError(file, "file", "cannot move the written image into place: " + ec.message(),
                         "check permissions of the target directory");
    }
}

}  // namespace voxlight::io

namespace voxlight::io {

ImageRGBA readHdrImage(const std::filesystem::path& path) {
    ImageReadInfo info;
    ImageRGBA img = readImage(path, info);
    if (!info.floatingPoint)
        throw InputError(path.string(), "format",
                         "is an integer (" + info.format +
                             ") image, not HDR: environment lights need linear radiance",
                         "convert the map to .hdr or .exr");
    return img;
}

}  // namespace voxlight::io
