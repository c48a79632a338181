// SPDX-License-Identifier: MIT
#pragma once
// Image files (OpenImageIO) to and from core::ImageRGBA: environment maps in, the renderer's output
// out.
//
// Values read are linear radiance for HDR formats (.hdr, .exr, .pfm, float TIFF). For 8/16-bit
// formats (.png, .jpg …) readImage returns the stored values scaled to 0..1 with no colour-space
// conversion (display-encoded, usually sRGB) — ImageReadInfo::floatingPoint tells the caller which
// case it got.
//
// readImage: any format OpenImageIO reads. 1 channel → (v, v, v, 1); 2 → (v, v, v, a);
// 3 → (r, g, b, 1); ≥ 4 → the first four. Missing file, unreadable/corrupt data or zero size →
// InputError naming the file and what to do. writeImage: format by extension. .exr → linear float
// (or half, WriteOptions) RGBA; .hdr → RGBE (alpha dropped); .png/.jpg/.tif/.bmp → 8-bit, the
// caller provides display values in 0..1 which are clamped and rounded (NaN/Inf → InputError, as
// they would otherwise silently become 0 or 255). The file is written to a temporary name in the
// same directory and renamed, so a crash never leaves a half-written file.
//
// OpenImageIO is loaded on the first call (libvoxlight_image_oiio.so, beside the executable; see
// image_module.h), so processes that never touch an image do not pay its start-up. When the module
// cannot be loaded, every call throws InputError (field "image module") listing where it looked.
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "core/image.h"

namespace voxlight::io {

using core::ImageRGBA;

/// What the file held before promotion to float RGBA.
struct ImageReadInfo {
    int channels = 0;            ///< channels in the file
    bool floatingPoint = false;  ///< half/float/double pixels (HDR) rather than integers
    std::string format;          ///< OpenImageIO's format name, e.g. "openexr", "hdr", "png"
};

ImageRGBA readImage(const std::filesystem::path& path);
ImageRGBA readImage(const std::filesystem::path& path, ImageReadInfo& info);

struct ImageWriteOptions {
    bool exrHalf = false;  ///< .exr: 16-bit half instead of 32-bit float
};
/// An HDR image for linear radiance (environment maps): readImage, then InputError (field "format")
/// when the file stores integers (an 8-bit PNG/JPEG is display-encoded, not radiance).
ImageRGBA readHdrImage(const std::filesystem::path& path);

/// Loads the image module on a background thread while the caller works on; the first image read
/// or write then finds it loaded, or waits for the rest of the load instead of doing all of it.
/// OpenImageIO maps, relocates and initialises ~250 libraries on load: 0.5–0.65 s of one core on
/// the development machine, which `voxlight render` paid after the image was ready. Started where
/// a command knows it will write an image, the load overlaps the volume read (one core) and the
/// precompute. Never throws (a load failure is reported by the first read or write, as without
/// it); the destructor waits for the loader.
class ImageModulePreload {
  public:
    ImageModulePreload();
    ~ImageModulePreload();
    ImageModulePreload(const ImageModulePreload&) = delete;
    ImageModulePreload& operator=(const ImageModulePreload&) = delete;

  private:
    std::thread loader_;
};

void writeImage(const ImageRGBA& image, const std::filesystem::path& path);
void writeImage(const ImageRGBA& image, const std::filesystem::path& path,
                const ImageWriteOptions& options);

}  // namespace voxlight::io
