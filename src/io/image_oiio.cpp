// SPDX-License-Identifier: MIT
// The OpenImageIO module (libvoxlight_image_oiio.so): the only code that includes OpenImageIO,
// loaded by io/image.cpp on the first image read or write (see image_module.h for why). No GDCM/VTK
// includes here: their headers clash (BUILD-NOTES).
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <array>
#include <exception>
#include <string>

#include "io/image_module.h"

namespace voxlight::io::image_module {

namespace {
std::string oiioError(const std::string& fromObject) {
    std::string e = fromObject.empty() ? OIIO::geterror() : fromObject;
    while (!e.empty() && (e.back() == '\n' || e.back() == ' ')) e.pop_back();
    // One line: OpenImageIO joins a codec's several complaints with newlines (they reached the
    // message as literal "\x0A").
    std::string line;
    for (const char c : e) {
        if (c == '\n' || c == '\r') {
            if (!line.empty() && line.back() != ' ') line += "; ";
        } else {
            line += c;
        }
    }
    return line.empty() ? "unknown OpenImageIO error" : line;
}

OIIO::TypeDesc toOiio(PixelType t) {
    switch (t) {
        case PixelType::Half:
            return OIIO::TypeDesc::HALF;
        case PixelType::UInt8:
            return OIIO::TypeDesc::UINT8;
        case PixelType::Float:
            break;
    }
    return OIIO::TypeDesc::FLOAT;
}

void readImpl(const char* path, std::uint64_t maxPixels, ReadResult& out) {
    auto in = OIIO::ImageInput::open(path);
    if (!in) {
        out.status = Status::OpenFailed, out.message = oiioError({});
        return;
    }
    const OIIO::ImageSpec& spec = in->spec();
    out.width = spec.width, out.height = spec.height, out.channels = spec.nchannels;
    out.floatingPoint = spec.format.is_floating_point();
    out.format = in->format_name();
    if (out.width <= 0 || out.height <= 0 || out.channels <= 0) {
        out.status = Status::ZeroSize;
        return;
    }
    if (std::uint64_t(out.width) * std::uint64_t(out.height) > maxPixels) {
        out.status = Status::TooLarge;
        return;
    }
    // The channels read, in order: the first (up to) four, or an EXR's colour channels by name.
    std::array<int, 4> source = {0, 1, 2, 3};
    int used = std::min(out.channels, 4);
    if (out.format == "openexr") {
        auto find = [&](const char* name) {
            for (int c = 0; c < spec.nchannels; ++c)
                if (spec.channel_name(c) == name) return c;
            return -1;
        };
        const int r = find("R"), g = find("G"), b = find("B"), a = find("A"), y = find("Y");
        if (r >= 0 && g >= 0 && b >= 0) {
            source = {r, g, b, a}, used = a >= 0 ? 4 : 3;
        } else if (y >= 0) {
            source = {y, a, -1, -1}, used = a >= 0 ? 2 : 1;
        } else if (r >= 0 || g >= 0 || b >= 0 || a >= 0) {
            // Part of a colour set (R alone, R and G): by position, as other formats.
        } else {
            out.status = Status::NoColour;
            for (int c = 0; c < spec.nchannels; ++c)
                out.message += (c ? ", " : "") + std::string(spec.channel_name(c));
            return;
        }
    }
    out.used = used;
    out.pixels.resize(std::size_t(out.width) * out.height * used);
    const OIIO::stride_t pixelBytes = OIIO::stride_t(used * sizeof(float));
    bool inOrder = true;  // the file's first `used` channels: one read
    for (int k = 0; k < used; ++k) inOrder = inOrder && source[std::size_t(k)] == k;
    for (int k = 0; k < (inOrder ? 1 : used); ++k) {
        const int first = source[std::size_t(k)], last = inOrder ? used : first + 1;
        if (!in->read_image(0, 0, first, last, OIIO::TypeDesc::FLOAT, out.pixels.data() + k,
                            pixelBytes)) {
            out.status = Status::DecodeFailed, out.message = oiioError(in->geterror());
            out.pixels.clear();
            return;
        }
    }
    in->close();
    out.status = Status::Ok;
}

void writeImpl(const WriteRequest& r, WriteResult& out) {
    auto o = OIIO::ImageOutput::create(r.path);
    if (!o) {
        out.status = Status::NoWriter, out.message = oiioError({});
        return;
    }
    OIIO::ImageSpec spec(r.width, r.height, r.channels, toOiio(r.type));
    if (r.zipCompression) spec.attribute("compression", "zip");
    if (!o->open(r.path, spec) || !o->write_image(OIIO::TypeDesc::FLOAT, r.pixels) || !o->close()) {
        out.status = Status::WriteFailed, out.message = oiioError(o->geterror());
        return;
    }
    out.status = Status::Ok;
}

// The entry points are noexcept: an exception must not unwind into the loader's frames, so
// anything OpenImageIO (or an allocation) throws becomes Status::Exception.
void read(const char* path, std::uint64_t maxPixels, ReadResult& out) noexcept {
    try {
        readImpl(path, maxPixels, out);
    } catch (const std::exception& e) {
        out.status = Status::Exception, out.message = e.what();
    } catch (...) {
        out.status = Status::Exception, out.message = "unknown exception in OpenImageIO";
    }
}

void write(const WriteRequest& request, WriteResult& out) noexcept {
    try {
        writeImpl(request, out);
    } catch (const std::exception& e) {
        out.status = Status::Exception, out.message = e.what();
    } catch (...) {
        out.status = Status::Exception, out.message = "unknown exception in OpenImageIO";
    }
}

constexpr Api kApi{kAbiVersion, &read, &write};
}  // namespace

}  // namespace voxlight::io::image_module

// The single exported symbol (the module is built with hidden visibility).
extern "C" __attribute__((visibility("default"))) const void* voxlight_image_module() {
    return &voxlight::io::image_module::kApi;
}
