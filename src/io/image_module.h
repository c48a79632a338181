// SPDX-License-Identifier: MIT
#pragma once
// Internal to io/: the seam between io/image.cpp and the OpenImageIO module
// (libvoxlight_image_oiio.so, built from image_oiio.cpp).
//
// Why a module: OpenImageIO pulls in ~280 shared libraries. Linked into the executable they are all
// mapped and relocated before main() — 0.4 s and 140 MB for `voxlight --version`. As a dlopen'ed
// module they are paid only by a process that actually reads or writes an image.
//
// The module does only what needs OpenImageIO: decode a file to interleaved floats, encode floats to
// a file. Validation, channel promotion, temporary names and every user-facing message stay in
// image.cpp, so the module returns a status and OpenImageIO's own error text, never an exception.
// Both sides are built by the same build with the same compiler, flags and libstdc++, so
// std::string / std::vector may cross; kAbiVersion guards against a stale module left beside a
// newer executable.
#include <cstdint>
#include <string>
#include <vector>

namespace voxlight::io::image_module {

/// Bumped whenever Api, ReadResult or WriteRequest change layout or meaning.
inline constexpr int kAbiVersion = 2;  // 2: Status::NoColour, EXR channels chosen by name
/// The module's file name (looked up beside the executable, then in the build tree).
inline constexpr const char* kFileName = "libvoxlight_image_oiio.so";
/// The one symbol the module exports: `const void* voxlight_image_module()` returning an Api.
inline constexpr const char* kEntryPoint = "voxlight_image_module";

enum class Status : int {
    Ok = 0,
    OpenFailed,    ///< not an image OpenImageIO recognises (message: OpenImageIO's reason)
    ZeroSize,      ///< width, height or channel count ≤ 0 (sizes are filled in)
    TooLarge,      ///< more than maxPixels pixels (sizes are filled in)
    DecodeFailed,  ///< header read, pixels not (truncated or corrupt)
    NoWriter,      ///< no OpenImageIO writer for the extension
    WriteFailed,   ///< open/write/close of the output failed
    Exception,     ///< a C++ exception inside the module (message: what())
    NoColour,      ///< an EXR with no R, G, B or Y channel (message: the channels it has)
};

struct ReadResult {
    Status status = Status::Ok;
    std::string message;                      ///< OpenImageIO's error text when status != Ok
    int width = 0, height = 0, channels = 0;  ///< as stored in the file
    /// Channels decoded into `pixels` (1 grey, 2 grey + alpha, 3 RGB, 4 RGBA): the first four, or
    /// an EXR's chosen by name (R, G, B, A or Y, A — a depth channel Z after RGB was read as
    /// alpha, a Z-only file as grey).
    int used = 0;
    bool floatingPoint = false;  ///< half/float/double pixels
    std::string format;          ///< OpenImageIO's format name ("openexr", "png" …)
    /// width·height·used floats, interleaved: only the channels image.cpp uses are
    /// decoded (a many-channel EXR would otherwise allocate all of them).
    std::vector<float> pixels;
};

enum class PixelType : int { Float, Half, UInt8 };

struct WriteRequest {
    const char* path = nullptr;  ///< written as is (the caller picks a temporary name)
    int width = 0, height = 0, channels = 0;
    PixelType type = PixelType::Float;  ///< stored type; pixels are always given as float
    bool zipCompression = false;        ///< EXR "zip" compression
    const float* pixels = nullptr;      ///< width·height·channels floats, interleaved
};

struct WriteResult {
    Status status = Status::Ok;
    std::string message;
};

struct Api {
    int abiVersion;  ///< first member (module_loader.h)
    /// Decodes `path`; files with more than maxPixels pixels are refused before allocating.
    void (*read)(const char* path, std::uint64_t maxPixels, ReadResult& out) noexcept;
    void (*write)(const WriteRequest& request, WriteResult& out) noexcept;
};

}  // namespace voxlight::io::image_module
