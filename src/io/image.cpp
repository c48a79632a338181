// SPDX-License-Identifier: MIT
// Image I/O front end: validation, channel promotion, temporary names and every message live here;
// the OpenImageIO calls live in a module loaded with dlopen on first use (image_module.h says why).
#include "io/image.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <string>
#include <system_error>

#include "core/error.h"
#include "core/files.h"
#include "io/image_module.h"
#include "io/module_loader.h"

namespace voxlight::io {

namespace {
namespace mod = image_module;

/// Images larger than this are refused before decoding (2^28 float RGBA pixels = 4 GiB).
constexpr std::uint64_t kMaxImagePixels = std::uint64_t(1) << 28;

std::string lowerExtension(const std::filesystem::path& p) {
    std::string e = p.extension().string();
    std::transform(e.begin(), e.end(), e.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return e;
}

/// The module's functions, loaded once per process (thread-safe); InputError naming `file` when the
/// module cannot be loaded.
const detail::LoadedModule& loadedImageModule() {
    static std::once_flag once;
    static detail::LoadedModule loaded;
    std::call_once(once, [] {
        loaded = detail::loadModule(mod::kFileName, mod::kEntryPoint, mod::kAbiVersion);
    });
    return loaded;
}

const mod::Api& imageModule(const std::string& file) {
    const detail::LoadedModule& loaded = loadedImageModule();
    if (!loaded.api)
        throw InputError(file, "image module",
                         "image support (OpenImageIO) is unavailable: " + loaded.error,
                         std::string("put ") + mod::kFileName +
                             " (built with voxlight) beside the voxlight executable");
    return *static_cast<const mod::Api*>(loaded.api);
}
}  // namespace

ImageModulePreload::ImageModulePreload() {
    detail::beginModuleLoad();  // before the thread exists: no fork slips in between
    try {
        loader_ = std::thread([] {
            try {
                (void)loadedImageModule();
            } catch (...) {
                // Out of memory while loading: the first read or write retries and reports it.
            }
            detail::endModuleLoad();
        });
    } catch (...) {
        // No thread to spare (system_error, or bad_alloc for its state): the first read or write
        // loads the module itself. The count must not stay up: every later fork would wait on it.
        detail::endModuleLoad();
    }
}

ImageModulePreload::~ImageModulePreload() {
    if (loader_.joinable()) loader_.join();
}

// --- Reading --------------------------------------------------------------------------------------

ImageRGBA readImage(const std::filesystem::path& path) {
    ImageReadInfo info;
    return readImage(path, info);
}

namespace {
/// Holds what is written to file descriptor 2 while it lives (libpng's default error handler,
/// which OpenImageIO's PNG reader leaves in place, prints "libpng error: …" there itself: a
/// second line beside voxlight's one). release() restores stderr and returns the text.
class StderrCapture {
  public:
    StderrCapture() {
        std::fflush(stderr);
        file_ = std::tmpfile();
        if (!file_) return;
        saved_ = ::dup(STDERR_FILENO);
        if (saved_ < 0 || ::dup2(::fileno(file_), STDERR_FILENO) < 0) {
            if (saved_ >= 0) ::close(saved_);
            saved_ = -1;
            std::fclose(file_);
            file_ = nullptr;
        }
    }
    StderrCapture(const StderrCapture&) = delete;
    StderrCapture& operator=(const StderrCapture&) = delete;
    ~StderrCapture() { (void)release(); }
    std::string release() {
        if (saved_ < 0) return {};
        std::fflush(stderr);
        ::dup2(saved_, STDERR_FILENO);
        ::close(saved_);
        saved_ = -1;
        std::string text;
        std::rewind(file_);
        char buffer[4096];
        std::size_t n = 0;
        while ((n = std::fread(buffer, 1, sizeof buffer, file_)) > 0) text.append(buffer, n);
        std::fclose(file_);
        file_ = nullptr;
        return text;
    }

  private:
    std::FILE* file_ = nullptr;
    int saved_ = -1;
};
}  // namespace

ImageRGBA readImage(const std::filesystem::path& path, ImageReadInfo& info) {
    const std::string file = path.string();
    std::error_code ec;
    if (!std::filesystem::exists(path, ec))
        throw InputError(file, "file", "image file does not exist", "check the path");
    if (std::filesystem::is_directory(path, ec))
        throw InputError(file, "file", "is a directory, not an image file",
                         "give the path of an image file");
    core::refuseSpecialFile(path);
    mod::ReadResult r;
    {
        const mod::Api& api = imageModule(file);  // (a loading error is reported as it is)
        // One capture at a time (the viewer's two pipeline threads may both read an environment
        // map): overlapping ones would leave stderr pointing at the other's temporary file.
        static std::mutex captureMutex;
        const std::lock_guard<std::mutex> lock(captureMutex);
        StderrCapture capture;
        api.read(file.c_str(), kMaxImagePixels, r);
        // Printed again, but for libpng's own lines when the read failed (the error carries
        // them); other threads' lines written meanwhile are kept either way.
        const std::string said = capture.release();
        std::size_t start = 0;
        while (start < said.size()) {
            std::size_t end = said.find('\n', start);
            end = end == std::string::npos ? said.size() : end + 1;
            const std::string line = said.substr(start, end - start);
            if (r.status == mod::Status::Ok || line.rfind("libpng", 0) != 0)
                std::fputs(line.c_str(), stderr);
            start = end;
        }
    }
    info.channels = r.channels;
    info.floatingPoint = r.floatingPoint;
    info.format = r.format;
    const int w = r.width, h = r.height, nc = r.channels;
    switch (r.status) {
        case mod::Status::Ok:
            break;
        case mod::Status::OpenFailed:
            throw InputError(
                file, "file", "cannot be read as an image: " + r.message,
                "give a valid .hdr, .exr, .png or .jpg file; is it truncated or mislabelled?");
        case mod::Status::ZeroSize:
            throw InputError(file, "size",
                             "image has zero size (" + std::to_string(w) + "×" + std::to_string(h) +
                                 ", " + std::to_string(nc) + " channels)",
                             "give a non-empty image");
        case mod::Status::TooLarge:
            throw InputError(file, "size",
                             "image is " + std::to_string(w) + "×" + std::to_string(h) +
                                 ", larger than the 2^28-pixel limit",
                             "downsample the image");
        case mod::Status::NoColour:
            throw InputError(file, "channels",
                             "has no colour channel (R, G, B or Y); its channels are " + r.message,
                             "write the image's colour into R, G and B (or Y)");
        default:
            throw InputError(file, "pixels", "pixel data cannot be decoded: " + r.message,
                             "the file is probably truncated or corrupt; re-export it");
    }
    const int used = r.used;
    VL_CHECK(used >= 1 && used <= 4 && r.pixels.size() == std::size_t(w) * h * used);

    // Promote to RGBA: grey → (v, v, v), missing alpha → 1.
    ImageRGBA img(w, h);
    for (std::size_t p = 0; p < std::size_t(w) * h; ++p) {
        const float* s = &r.pixels[p * used];
        float* d = &img.pixels[p * 4];
        if (used <= 2) {
            d[0] = d[1] = d[2] = s[0];
            d[3] = used == 2 ? s[1] : 1.0f;
        } else {
            d[0] = s[0], d[1] = s[1], d[2] = s[2];
            d[3] = used == 4 ? s[3] : 1.0f;
        }
    }
    return img;
}

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

// --- Writing --------------------------------------------------------------------------------------

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
    mod::PixelType type = mod::PixelType::Float;
    if (exr && options.exrHalf) type = mod::PixelType::Half;
    if (eightBit) type = mod::PixelType::UInt8;
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
    const mod::Api& api = imageModule(file);
    const std::filesystem::path dir =
        path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
    // libjpeg ends the process (exit(1)) when its output fails, as on a full disk: no error comes
    // back to refuse. A rendered image's JPEG is far below its raw pixels; twice them plus the
    // headers is a bound with room (noise at quality 100 comes near the raw size, not past 2×).
    constexpr std::int64_t kJpegHeaderBytes = 1 << 16;
    const bool jpeg = ext == ".jpg" || ext == ".jpeg";
    if (jpeg) {
        const std::int64_t free = core::freeBytes(dir);
        if (free >= 0 && free < 2 * std::int64_t(w) * h * channels + kJpegHeaderBytes)
            throw core::noSpaceLeft(file);
    }

    // A short temporary name in the same directory (the target's may be near the file system's
    // limit), same extension (OpenImageIO picks the format from it).
    static std::atomic<int> counter{0};
    const std::filesystem::path tmp = dir / (".voxlight-image-" + std::to_string(::getpid()) + "-" +
                                             std::to_string(counter++) + path.extension().string());
    const std::string tmpName = tmp.string();
    mod::WriteRequest request;
    request.path = tmpName.c_str();
    request.width = w, request.height = h, request.channels = channels;
    request.type = type;
    request.zipCompression = exr;
    request.pixels = data.data();
    mod::WriteResult result;
    api.write(request, result);
    if (result.status == mod::Status::NoWriter)
        throw InputError(file, "extension",
                         "no image writer for \"" + ext + "\": " + result.message,
                         "use .exr (linear HDR), .hdr or .png");
    // OpenImageIO's PNG and BMP writers report success over a short file when the disk fills
    // (core::fileSystemFull); the others' messages name this temporary.
    if (const bool full = core::fileSystemFull(dir); result.status != mod::Status::Ok || full) {
        std::error_code ec;
        std::filesystem::remove(tmp, ec);  // frees the space: asked before
        if (full) throw core::noSpaceLeft(file);
        throw InputError(file, "file", "cannot write image: " + result.message,
                         "check that the directory exists and is writable");
    }
    // OpenImageIO's PNG and BMP writers also report success over a short file when a write
    // fails for another reason (a disk quota, the file size limit): such a file does not read
    // back. One decode of the file just written (8-bit images; not timed separately).
    if (eightBit && !jpeg) {
        bool whole = false;
        try {
            ImageReadInfo info;
            const ImageRGBA back = readImage(tmp, info);
            whole = back.width == w && back.height == h;
        } catch (const InputError&) {
        }
        if (!whole) {
            std::error_code ec;
            std::filesystem::remove(tmp, ec);
            throw InputError(file, "file",
                             "was not written whole: it does not read back (a write error the "
                             "image library did not report)",
                             "check free space, disk quotas and the file size limit (ulimit -f)");
        }
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
