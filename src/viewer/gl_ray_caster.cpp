// SPDX-License-Identifier: MIT
#include "viewer/gl_ray_caster.h"

// OpenGL 4.5 entry points straight from libGL (Mesa / glvnd export the whole core API).
#define GL_GLEXT_PROTOTYPES 1
#include <GL/gl.h>
#include <GL/glext.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/rng.h"
#include "core/timing.h"
#include "render/ray_caster.h"
#include "render/sh_shading.h"
#include "render/shading.h"
#include "viewer/embedded_shaders.h"
#include "viewer/gl_support.h"

namespace voxlight::viewer {

namespace {

/// Rows of the TF texture (shaders/raycast.frag says what each holds).
constexpr int kTfRows = 8;
/// First texture units of the SH field's and sh-global's local field's textures (4 each).
constexpr int kShFieldUnit = 4, kShLocalUnit = 8, kShSpacingUnit = 12;
/// Texels per glTextureSubImage3D call of a sliced upload (GlRayCaster::upload), or one whole
/// z-slice where a slice holds more: 128 kB of a 16-bit volume, 512 kB of an RGBA16F field (a 512²
/// CT slice: 512 kB) — well under a millisecond to copy, so a UI frame's budget is overrun by
/// less than one slab.
constexpr std::size_t kUploadSlabTexels = std::size_t(1) << 16;

/// Whether sh-global's draw also reads the local field (within the band of a face that removes
/// matter for the light).
bool blendsLocalField(const pipeline::CasterSetup& setup) {
    return setup.sh.global && setup.sh.cutBandMm > 0.f &&
           !render::lightCutFaces(setup.options).empty();
}

/// The first line of a shader or program info log.
std::string firstLine(const std::string& log) {
    const std::size_t end = log.find('\n');
    return end == std::string::npos ? log : log.substr(0, end);
}

GLuint compile(GLenum kind, const char* source, const char* name, std::string& why) {
    const GLuint s = glCreateShader(kind);
    glShaderSource(s, 1, &source, nullptr);
    glCompileShader(s);
    GLint ok = GL_FALSE;
    glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (ok == GL_TRUE) return s;
    GLint n = 0;
    glGetShaderiv(s, GL_INFO_LOG_LENGTH, &n);
    std::string log(std::size_t(std::max(n, 1)), '\0');
    glGetShaderInfoLog(s, n, nullptr, log.data());
    why = std::string(name) + " does not compile: " + firstLine(log.c_str());
    glDeleteShader(s);
    return 0;
}

GLuint link(const char* vertex, const char* fragment, const char* name, std::string& why) {
    const GLuint vs = compile(GL_VERTEX_SHADER, vertex, "fullscreen.vert", why);
    if (!vs) return 0;
    const GLuint fs = compile(GL_FRAGMENT_SHADER, fragment, name, why);
    if (!fs) {
        glDeleteShader(vs);
        return 0;
    }
    const GLuint p = glCreateProgram();
    glAttachShader(p, vs);
    glAttachShader(p, fs);
    glLinkProgram(p);
    glDeleteShader(vs);
    glDeleteShader(fs);
    GLint ok = GL_FALSE;
    glGetProgramiv(p, GL_LINK_STATUS, &ok);
    if (ok == GL_TRUE) return p;
    GLint n = 0;
    glGetProgramiv(p, GL_INFO_LOG_LENGTH, &n);
    std::string log(std::size_t(std::max(n, 1)), '\0');
    glGetProgramInfoLog(p, n, nullptr, log.data());
    why = std::string(name) + " does not link: " + firstLine(log.c_str());
    glDeleteProgram(p);
    return 0;
}

/// Drains the GL error queue; the first error as text, or empty.
std::string glErrorText() {
    std::string first;
    for (GLenum e = glGetError(); e != GL_NO_ERROR; e = glGetError())
        if (first.empty()) {
            char buf[32];
            std::snprintf(buf, sizeof buf, "GL error 0x%04x", unsigned(e));
            first = buf;
        }
    return first;
}

// Uniform setters by name (a missing name — optimised away — is location −1, which GL ignores).
struct Uniforms {
    GLuint p;
    GLint at(const char* n) const { return glGetUniformLocation(p, n); }
    void f(const char* n, float v) const { glProgramUniform1f(p, at(n), v); }
    void i(const char* n, int v) const { glProgramUniform1i(p, at(n), v); }
    void v2(const char* n, const glm::vec2& v) const { glProgramUniform2f(p, at(n), v.x, v.y); }
    void v3(const char* n, const glm::vec3& v) const {
        glProgramUniform3f(p, at(n), v.x, v.y, v.z);
    }
    void m3(const char* n, const glm::mat3& m) const {
        glProgramUniformMatrix3fv(p, at(n), 1, GL_FALSE, &m[0][0]);
    }
    std::string indexed(const char* n, int k) const {
        return std::string(n) + "[" + std::to_string(k) + "]";
    }
};

/// A finite stand-in for ±∞ in uniforms (TfTable's transparent tails).
float finite(float v) { return std::clamp(v, -1e30f, 1e30f); }

}  // namespace

GlRayCaster::~GlRayCaster() { release(); }

void GlRayCaster::release() {
    const GLuint textures[] = {volumeTex_, tfTex_, jitterTex_, skipTex_, filmTex_, displayTex_};
    for (GLuint t : textures)
        if (t) glDeleteTextures(1, &t);
    if (filmFbo_) glDeleteFramebuffers(1, &filmFbo_);
    if (displayFbo_) glDeleteFramebuffers(1, &displayFbo_);
    if (vao_) glDeleteVertexArrays(1, &vao_);
    if (raycast_) glDeleteProgram(raycast_);
    if (display_) glDeleteProgram(display_);
    for (ShUpload& up : shUploaded_)
        for (GLuint t : up.textures)
            if (t) glDeleteTextures(1, &t);
    shUploaded_.clear();
    volumeTex_ = tfTex_ = jitterTex_ = skipTex_ = filmTex_ = displayTex_ = 0;
    filmFbo_ = displayFbo_ = 0;
    vao_ = raycast_ = display_ = 0;
}

bool GlRayCaster::init(std::string& why) {
    GLint major = 0, minor = 0;
    glGetIntegerv(GL_MAJOR_VERSION, &major);
    glGetIntegerv(GL_MINOR_VERSION, &minor);
    const char* r = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
    renderer_ = r ? r : "unknown";
    if (major < 4 || (major == 4 && minor < 5)) {
        why = "the OpenGL context is " + std::to_string(major) + "." + std::to_string(minor) +
              " (" + renderer_ + "); the GLSL ray caster needs 4.5";
        glErrorText();
        return false;
    }
    raycast_ = link(shaders::kFullscreenVert, shaders::kRaycastFrag, "raycast.frag", why);
    if (raycast_)
        display_ = link(shaders::kFullscreenVert, shaders::kDisplayFrag, "display.frag", why);
    if (!raycast_ || !display_) {
        release();
        glErrorText();
        return false;
    }
    glCreateVertexArrays(1, &vao_);
    if (const std::string e = glErrorText(); !e.empty()) {
        why = "setting up the GLSL ray caster: " + e;
        release();
        return false;
    }
    return true;
}

GlRayCaster::Upload GlRayCaster::upload(const pipeline::CasterSetup& setup, const ShGrids& sh,
                                        double seconds, std::string& why) {
    if (!ready()) {
        why = "the GLSL ray caster is not initialised";
        return Upload::Failed;
    }
    glErrorText();  // errors of others (ImGui's frame) are not ours
    core::Stopwatch sw;
    if (const Upload u = uploadVolume(setup.volume, seconds, why); u != Upload::Ready) return u;
    if (!(setup.sh.local || setup.sh.global || setup.sh.hierarchical) || !sh.field)
        return Upload::Ready;
    unsigned textures[4];
    if (const Upload u = shTextures(sh.field, textures, seconds - sw.seconds(), why);
        u != Upload::Ready)
        return u;
    if (sh.local && blendsLocalField(setup))
        return shTextures(sh.local, textures, seconds - sw.seconds(), why);
    return Upload::Ready;
}

GlRayCaster::Upload GlRayCaster::uploadVolume(const std::shared_ptr<const core::Volume>& volume,
                                              double seconds, std::string& why) {
    if (volume_ == volume && volumeTex_) return Upload::Ready;
    const glm::ivec3 n = volume->dims();
    const double slope = volume->mapping.slope, intercept = volume->mapping.intercept;
    const bool isFloat = volume->type() == core::VoxelType::Float32;
    if (volumePending_ != volume || !volumeTex_) {
        volume_.reset();
        volumePending_.reset();
        GLint max3d = 0;
        glGetIntegerv(GL_MAX_3D_TEXTURE_SIZE, &max3d);
        if (n.x > max3d || n.y > max3d || n.z > max3d) {
            why = "the volume (" + std::to_string(n.x) + "x" + std::to_string(n.y) + "x" +
                  std::to_string(n.z) + ") exceeds this GL's 3D textures (" +
                  std::to_string(max3d) + " per side)";
            return Upload::Failed;
        }
        if (volumeTex_) glDeleteTextures(1, &volumeTex_);
        volumeTex_ = 0;
        glCreateTextures(GL_TEXTURE_3D, 1, &volumeTex_);
        // Integer voxels as 16-bit unsigned normalised texels u (exact): stored = u + bias, so
        // physical = slope·(65535·texel + bias) + intercept. (8-bit texels would be filtered at
        // 8-bit precision by some GLs, llvmpipe among them.)
        const double bias = volume->type() == core::VoxelType::Int16 ? -32768.0 : 0.0;
        glTextureStorage3D(volumeTex_, 1, isFloat ? GL_R32F : GL_R16, n.x, n.y, n.z);
        valueScale_ = float(isFloat ? slope : slope * 65535.0);
        valueOffset_ = float(isFloat ? intercept : slope * bias + intercept);
        glTextureParameteri(volumeTex_, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
        glTextureParameteri(volumeTex_, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
        for (GLenum w : {GL_TEXTURE_WRAP_S, GL_TEXTURE_WRAP_T, GL_TEXTURE_WRAP_R})
            glTextureParameteri(volumeTex_, w, GL_CLAMP_TO_EDGE);
        if (const std::string e = glErrorText(); !e.empty()) {
            why = "allocating the volume's 3D texture: " + e;
            glDeleteTextures(1, &volumeTex_);
            volumeTex_ = 0;
            return Upload::Failed;
        }
        volumePending_ = volume;
        volumeZ_ = 0;
        // The storage can be the dear part (llvmpipe zero-fills it): a budgeted call stops here.
        if (std::isfinite(seconds)) return Upload::Progress;
    }
    // Slabs of whole z-slices, each converted and copied in one call, until `seconds` are spent.
    core::Stopwatch sw;
    const std::size_t slice = std::size_t(n.x) * std::size_t(n.y);
    const int slab = int(std::clamp(kUploadSlabTexels / slice, std::size_t(1), std::size_t(n.z)));
    std::vector<std::uint16_t> u;
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    while (volumeZ_ < n.z) {
        const int z0 = volumeZ_, z1 = std::min(n.z, z0 + slab);
        const std::size_t first = slice * std::size_t(z0), count = slice * std::size_t(z1 - z0);
        const void* data = nullptr;
        switch (volume->type()) {
            case core::VoxelType::Float32:
                data = static_cast<const float*>(volume->data()) + first;
                break;
            case core::VoxelType::Int16: {
                const auto* s = static_cast<const std::int16_t*>(volume->data()) + first;
                u.resize(count);
                for (std::size_t i = 0; i < count; ++i) u[i] = std::uint16_t(int(s[i]) + 32768);
                data = u.data();
                break;
            }
            case core::VoxelType::UInt8: {
                const auto* s = static_cast<const std::uint8_t*>(volume->data()) + first;
                u.assign(s, s + count);
                data = u.data();
                break;
            }
            case core::VoxelType::UInt16:
                data = static_cast<const std::uint16_t*>(volume->data()) + first;
                break;
        }
        glTextureSubImage3D(volumeTex_, 0, 0, 0, z0, n.x, n.y, z1 - z0, GL_RED,
                            isFloat ? GL_FLOAT : GL_UNSIGNED_SHORT, data);
        volumeZ_ = z1;
        if (std::isfinite(seconds)) glFinish();  // a GL may queue the copy: its real cost
        if (sw.seconds() >= seconds) break;
    }
    if (const std::string e = glErrorText(); !e.empty()) {
        why = "uploading the volume as a 3D texture: " + e;
        glDeleteTextures(1, &volumeTex_);
        volumeTex_ = 0;
        volumePending_.reset();
        return Upload::Failed;
    }
    if (volumeZ_ >= n.z) volume_ = volume, volumePending_.reset();
    return Upload::Progress;
}

void GlRayCaster::uploadTable(const optics::TfTable& table) {
    const optics::TfTable::Nodes nodes = table.nodes();
    const int w = int(nodes.sigma.size());
    std::vector<float> texels(std::size_t(w) * kTfRows * 4, 0.f);
    auto put = [&](int row, int i, float a, float b, float c, float d) {
        float* p = &texels[(std::size_t(row) * w + std::size_t(i)) * 4];
        p[0] = a, p[1] = b, p[2] = c, p[3] = d;
    };
    for (int i = 0; i < w; ++i) {
        const auto& f = nodes.weighted[std::size_t(i)];
        put(0, i, nodes.sigma[std::size_t(i)], f[0], f[1], f[2]);
        put(1, i, f[3], f[4], f[5], 0.f);
        // Cumulative integrals as float pairs hi + lo (the CPU keeps them in double).
        double cum[8] = {nodes.cumSigma[std::size_t(i)], 0, 0, 0, 0, 0, 0, 0};
        for (int c = 0; c < 6; ++c) cum[1 + c] = nodes.cumWeighted[std::size_t(i)][std::size_t(c)];
        float hi[8], lo[8];
        for (int c = 0; c < 8; ++c) {
            hi[c] = float(cum[c]);
            lo[c] = float(cum[c] - double(hi[c]));
        }
        put(2, i, hi[0], hi[1], hi[2], hi[3]);
        put(3, i, lo[0], lo[1], lo[2], lo[3]);
        put(4, i, hi[4], hi[5], hi[6], 0.f);
        put(5, i, lo[4], lo[5], lo[6], 0.f);
        const glm::vec3 a = nodes.albedo[std::size_t(i)], e = nodes.emission[std::size_t(i)];
        put(6, i, a.r, a.g, a.b, nodes.sigma[std::size_t(i)]);
        put(7, i, e.r, e.g, e.b, 0.f);
    }
    if (tfTex_) glDeleteTextures(1, &tfTex_);
    glCreateTextures(GL_TEXTURE_2D, 1, &tfTex_);
    glTextureStorage2D(tfTex_, 1, GL_RGBA32F, w, kTfRows);
    glTextureSubImage2D(tfTex_, 0, 0, 0, w, kTfRows, GL_RGBA, GL_FLOAT, texels.data());
    glTextureParameteri(tfTex_, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(tfTex_, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
}

void GlRayCaster::uploadSkipCells(const grid::BrickMajorants& cells) {
    const glm::ivec3 n = cells.counts();
    if (skipTex_) glDeleteTextures(1, &skipTex_);
    glCreateTextures(GL_TEXTURE_3D, 1, &skipTex_);
    glTextureStorage3D(skipTex_, 1, GL_R8UI, n.x, n.y, n.z);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTextureSubImage3D(skipTex_, 0, 0, 0, 0, n.x, n.y, n.z, GL_RED_INTEGER, GL_UNSIGNED_BYTE,
                        cells.skipDistances());
    glTextureParameteri(skipTex_, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(skipTex_, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
}

void GlRayCaster::uploadJitter(int width, int height, bool jitter, std::uint64_t seed) {
    // RayCaster::setupRay's per-pixel start offset, from the same counter-based hash.
    std::vector<float> j(std::size_t(width) * height, 0.f);
    if (jitter)
        for (int y = 0; y < height; ++y)
            for (int x = 0; x < width; ++x)
                j[std::size_t(y) * width + x] = core::toUnitFloat(core::hashCounters(
                    std::uint64_t(y) * std::uint64_t(width) + std::uint64_t(x), 0, 0, seed));
    if (jitterTex_) glDeleteTextures(1, &jitterTex_);
    glCreateTextures(GL_TEXTURE_2D, 1, &jitterTex_);
    glTextureStorage2D(jitterTex_, 1, GL_R32F, width, height);
    glTextureSubImage2D(jitterTex_, 0, 0, 0, width, height, GL_RED, GL_FLOAT, j.data());
    glTextureParameteri(jitterTex_, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(jitterTex_, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    jitterW_ = width, jitterH_ = height, jitterOn_ = jitter, jitterSeed_ = seed;
}

GlRayCaster::Upload GlRayCaster::shTextures(const std::shared_ptr<const render::ShFieldGrid>& grid,
                                            unsigned out[4], double seconds, std::string& why,
                                            unsigned* spacing) {
    // Texture t < grid->textures(): coefficients 4t…4t+3 (RGBA16F); then, when the grid has
    // one, its spacing (R16F).
    const int coefficientTextures = grid->textures();
    const int total = coefficientTextures + (grid->spacing.empty() ? 0 : 1);
    const auto handOut = [&](const ShUpload& up) {
        std::fill_n(out, 4, 0u);
        std::copy_n(up.textures, coefficientTextures, out);
        if (spacing) *spacing = total > coefficientTextures ? up.textures[coefficientTextures] : 0u;
    };
    std::size_t at = shUploaded_.size();
    for (std::size_t i = 0; i < shUploaded_.size(); ++i)
        if (shUploaded_[i].grid == grid) at = i;
    if (at < shUploaded_.size()) {
        std::rotate(shUploaded_.begin(), shUploaded_.begin() + std::ptrdiff_t(at),
                    shUploaded_.begin() + std::ptrdiff_t(at) + 1);
    } else {
        ShUpload up;
        up.grid = grid;
        const glm::ivec3 n = grid->res;
        for (int t = 0; t < total; ++t) {
            GLuint tex = 0;
            glCreateTextures(GL_TEXTURE_3D, 1, &tex);
            up.textures[t] = tex;
            glTextureStorage3D(tex, 1, t < coefficientTextures ? GL_RGBA16F : GL_R16F, n.x, n.y,
                               n.z);
            glTextureParameteri(tex, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
            glTextureParameteri(tex, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
            for (GLenum w : {GL_TEXTURE_WRAP_S, GL_TEXTURE_WRAP_T, GL_TEXTURE_WRAP_R})
                glTextureParameteri(tex, w, GL_CLAMP_TO_EDGE);
        }
        shUploaded_.insert(shUploaded_.begin(), up);
        if (shUploaded_.size() > kKeptShFields) {
            for (GLuint t : shUploaded_.back().textures)
                if (t) glDeleteTextures(1, &t);
            shUploaded_.pop_back();
        }
        if (const std::string e = glErrorText(); !e.empty()) {
            why = "allocating the SH visibility field's 3D textures (" + std::to_string(n.x) + "x" +
                  std::to_string(n.y) + "x" + std::to_string(n.z) + "): " + e;
            for (GLuint t : shUploaded_.front().textures)
                if (t) glDeleteTextures(1, &t);
            shUploaded_.erase(shUploaded_.begin());
            std::fill_n(out, 4, 0u);
            if (spacing) *spacing = 0u;
            return Upload::Failed;
        }
        // As for the volume: a budgeted call allocates the storage only.
        if (std::isfinite(seconds)) {
            handOut(up);
            return Upload::Progress;
        }
    }
    ShUpload& up = shUploaded_.front();
    handOut(up);
    if (up.texture >= total) return Upload::Ready;
    // Slabs of z-slices of one texture at a time, until `seconds` are spent.
    core::Stopwatch sw;
    const glm::ivec3 n = grid->res;
    const std::size_t slice = std::size_t(n.x) * std::size_t(n.y);
    const int slab = int(std::clamp(kUploadSlabTexels / slice, std::size_t(1), std::size_t(n.z)));
    while (up.texture < total) {
        const int z1 = std::min(n.z, up.z + slab);
        if (up.texture < coefficientTextures) {
            glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
            glTextureSubImage3D(
                up.textures[up.texture], 0, 0, 0, up.z, n.x, n.y, z1 - up.z, GL_RGBA, GL_HALF_FLOAT,
                grid->texels[std::size_t(up.texture)].data() + 4 * slice * std::size_t(up.z));
        } else {
            glPixelStorei(GL_UNPACK_ALIGNMENT, 2);  // rows of n.x half floats
            glTextureSubImage3D(up.textures[up.texture], 0, 0, 0, up.z, n.x, n.y, z1 - up.z, GL_RED,
                                GL_HALF_FLOAT, grid->spacing.data() + slice * std::size_t(up.z));
            glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
        }
        up.z = z1;
        if (std::isfinite(seconds)) glFinish();
        if (up.z >= n.z) ++up.texture, up.z = 0;
        if (up.texture < total && sw.seconds() >= seconds) break;
    }
    if (const std::string e = glErrorText(); !e.empty()) {
        why = "uploading the SH visibility field (" + std::to_string(n.x) + "x" +
              std::to_string(n.y) + "x" + std::to_string(n.z) + ", " +
              std::to_string(grid->coefficients) + " coefficients) as 3D textures: " + e;
        for (GLuint t : up.textures)
            if (t) glDeleteTextures(1, &t);
        shUploaded_.erase(shUploaded_.begin());
        std::fill_n(out, 4, 0u);
        if (spacing) *spacing = 0u;
        return Upload::Failed;
    }
    if (up.texture >= total) ++shUploads_;
    return Upload::Progress;
}

bool GlRayCaster::ensureTarget(unsigned& tex, unsigned& fbo, unsigned format, int width, int height,
                               std::string& why) {
    glCreateTextures(GL_TEXTURE_2D, 1, &tex);
    glTextureStorage2D(tex, 1, format, width, height);
    glTextureParameteri(tex, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(tex, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glTextureParameteri(tex, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTextureParameteri(tex, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    glCreateFramebuffers(1, &fbo);
    glNamedFramebufferTexture(fbo, GL_COLOR_ATTACHMENT0, tex, 0);
    const bool complete =
        glCheckNamedFramebufferStatus(fbo, GL_FRAMEBUFFER) == GL_FRAMEBUFFER_COMPLETE;
    const std::string e = glErrorText();
    if (!complete || !e.empty()) {
        why = "the GL render targets (" + std::to_string(width) + "x" + std::to_string(height) +
              ") are not usable" + (e.empty() ? "" : ": " + e);
        return false;
    }
    return true;
}

bool GlRayCaster::ensureFilm(int width, int height, std::string& why) {
    if (filmFbo_ && width == filmW_ && height == filmH_) return true;
    if (filmTex_) glDeleteTextures(1, &filmTex_), filmTex_ = 0;
    if (filmFbo_) glDeleteFramebuffers(1, &filmFbo_), filmFbo_ = 0;
    filmW_ = filmH_ = 0;
    if (!ensureTarget(filmTex_, filmFbo_, GL_RGBA32F, width, height, why)) return false;
    filmW_ = width, filmH_ = height;
    return true;
}

bool GlRayCaster::ensureDisplay(int width, int height, std::string& why) {
    if (displayFbo_ && width == width_ && height == height_) return true;
    if (displayTex_) glDeleteTextures(1, &displayTex_), displayTex_ = 0;
    if (displayFbo_) glDeleteFramebuffers(1, &displayFbo_), displayFbo_ = 0;
    width_ = height_ = 0;
    if (!ensureTarget(displayTex_, displayFbo_, GL_RGBA8, width, height, why)) return false;
    width_ = width, height_ = height;
    return true;
}

bool GlRayCaster::render(const pipeline::CasterSetup& setup, const ShGrids& sh, float exposureStops,
                         render::Display display, std::string& why, Scope scope) {
    const int w = setup.camera->width(), h = setup.camera->height();
    Rect r{0, 0, w, h};
    if (scope == Scope::WarmUp)
        r = {0, 0, std::min(w, kWarmUpPixels), std::min(h, kWarmUpPixels)};
    else if (scope == Scope::CentreQuarter)
        r = {w / 4, h / 4, std::max(w / 2, 1), std::max(h / 2, 1)};
    return draw(setup, sh, exposureStops, display, why, r, true);
}

bool GlRayCaster::renderRows(const pipeline::CasterSetup& setup, const ShGrids& sh,
                             float exposureStops, render::Display display, std::string& why,
                             int rowBegin, int rowEnd, bool finish) {
    return renderRect(setup, sh, exposureStops, display, why, 0, rowBegin, setup.camera->width(),
                      rowEnd - rowBegin, finish);
}

bool GlRayCaster::renderRect(const pipeline::CasterSetup& setup, const ShGrids& sh,
                             float exposureStops, render::Display display, std::string& why, int x0,
                             int y0, int w, int h, bool finish) {
    const int fw = setup.camera->width(), fh = setup.camera->height();
    const int xa = std::clamp(x0, 0, fw), ya = std::clamp(y0, 0, fh);
    const int xb = std::clamp(x0 + std::max(w, 0), xa, fw),
              yb = std::clamp(y0 + std::max(h, 0), ya, fh);
    return draw(setup, sh, exposureStops, display, why, {xa, ya, xb - xa, yb - ya}, finish);
}

bool GlRayCaster::draw(const pipeline::CasterSetup& setup, const ShGrids& sh, float exposureStops,
                       render::Display display, std::string& why, const Rect& rect, bool finish) {
    if (!ready()) {
        why = "the GLSL ray caster is not initialised";
        return false;
    }
    if (const std::string no = glUnsupportedReason(setup.method, &setup); !no.empty()) {
        why = no;
        return false;
    }
    glErrorText();  // errors of others (ImGui's frame) are not ours
    const core::Volume& volume = *setup.volume;
    const render::RenderOptions& o = setup.options;
    const render::Camera& camera = *setup.camera;
    // The caster's own derived constants (step, gradient matrix, boxes): no tables are built.
    render::RayCaster caster(setup.volume, setup.tf, o, setup.tables);
    if (uploadVolume(setup.volume, kUploadAll, why) == Upload::Failed) return false;
    if (table_ != setup.tables.table || !tfTex_) {
        uploadTable(*setup.tables.table);
        table_ = setup.tables.table;
    }
    if (skipCells_ != setup.tables.skipCells || !skipTex_) {
        uploadSkipCells(*setup.tables.skipCells);
        skipCells_ = setup.tables.skipCells;
    }
    // SH methods: the fields' textures (the local one only where sh-global needs it).
    const bool shMode = setup.sh.local || setup.sh.global || setup.sh.hierarchical;
    const std::vector<core::HalfSpace> faces = setup.sh.global && setup.sh.cutBandMm > 0.f
                                                   ? render::lightCutFaces(o)
                                                   : std::vector<core::HalfSpace>{};
    unsigned shField[4] = {0, 0, 0, 0}, shLocal[4] = {0, 0, 0, 0}, shSpacing = 0;
    const bool shBlend = shMode && blendsLocalField(setup);
    if (shMode) {
        if (!sh.field || (shBlend && !sh.local)) {
            why = "the SH visibility field was not resampled for the GLSL ray caster";
            return false;
        }
        if (shBlend &&
            (sh.local->res != sh.field->res || sh.local->coefficients != sh.field->coefficients)) {
            why = "sh-global's local and global fields were resampled on different grids";
            return false;
        }
        if (shTextures(sh.field, shField, kUploadAll, why, &shSpacing) == Upload::Failed)
            return false;
        if (shBlend && shTextures(sh.local, shLocal, kUploadAll, why) == Upload::Failed)
            return false;
    }
    const int w = camera.width(), h = camera.height();
    if (!ensureFilm(w, h, why) || (finish && !ensureDisplay(w, h, why))) return false;
    if (!jitterTex_ || jitterW_ != w || jitterH_ != h || jitterOn_ != o.jitter ||
        jitterSeed_ != o.seed)
        uploadJitter(w, h, o.jitter, o.seed);

    const Uniforms u{raycast_};
    const core::Geometry& g = volume.geometry();
    u.v3("uDims", glm::vec3(g.dims));
    u.f("uValueScale", valueScale_);
    u.f("uValueOffset", valueOffset_);
    glm::dmat3 worldToIndex = glm::transpose(g.direction);
    for (int c = 0; c < 3; ++c)
        for (int a = 0; a < 3; ++a) worldToIndex[c][a] /= g.spacing[a];
    u.m3("uWorldToIndex", glm::mat3(worldToIndex));
    u.v3("uOrigin", glm::vec3(g.origin));
    const auto box = caster.volumeIndexBox();
    u.v3("uIndexBoxLo", glm::vec3(box[0]));
    u.v3("uIndexBoxHi", glm::vec3(box[1]));
    // RayCaster::visibleRange's box: the non-empty cells' box, extended to the volume box where
    // it reaches the grid's edge, widened by kVisibleBoxMarginVoxels (as its constructor builds).
    std::array<glm::vec3, 2> visible = caster.visibleIndexBox();
    const bool any = visible[0].x <= visible[1].x;
    if (any)
        for (int a = 0; a < 3; ++a) {
            if (visible[0][a] <= 0.f) visible[0][a] = float(box[0][a]);
            if (visible[1][a] >= float(g.dims[a] - 1)) visible[1][a] = float(box[1][a]);
            visible[0][a] -= render::kVisibleBoxMarginVoxels;
            visible[1][a] += render::kVisibleBoxMarginVoxels;
        }
    u.i("uAnyVisible", any ? 1 : 0);
    u.v3("uVisibleLo", visible[0]);
    u.v3("uVisibleHi", visible[1]);
    u.m3("uGradientMatrix", caster.gradientMatrix());
    u.i("uSkip", o.emptySpaceSkipping ? 1 : 0);
    const glm::ivec3 cells = setup.tables.skipCells->counts();
    glProgramUniform3i(raycast_, u.at("uCellCounts"), cells.x, cells.y, cells.z);
    u.f("uCellSize", float(setup.tables.skipCells->cellSize()));

    const optics::TfTable& table = *setup.tables.table;
    u.i("uTfCells", optics::TfTable::kTableCells);
    u.f("uTfLo", table.lo());
    u.f("uTfInvCell", table.invCellWidth());
    u.f("uTfCell", table.cellWidth());
    u.i("uTfEmissive", table.hasEmission() ? 1 : 0);
    u.f("uZeroBelow", finite(table.zeroBelow()));
    u.f("uZeroAbove", finite(table.zeroAbove()));

    const render::Camera::PixelMap pm = camera.pixelMap();
    u.i("uPerspective", camera.projection() == render::Projection::Perspective ? 1 : 0);
    u.v3("uEye", glm::vec3(camera.eye()));
    u.v3("uForward", glm::vec3(camera.forward()));
    u.v3("uRightStep", glm::vec3(pm.rightStep));
    u.v3("uUpStep", glm::vec3(pm.upStep));
    u.v2("uPixelScale", glm::vec2(pm.pixelScale));

    u.i("uClipCount", int(o.clipPlanes.size()));
    for (std::size_t c = 0; c < o.clipPlanes.size(); ++c) {
        u.v3(u.indexed("uClipPoint", int(c)).c_str(), glm::vec3(o.clipPlanes[c].point));
        u.v3(u.indexed("uClipNormal", int(c)).c_str(), glm::vec3(o.clipPlanes[c].normal));
    }
    u.i("uHasCrop", o.cropBox ? 1 : 0);
    if (o.cropBox) {
        u.v3("uCropMin", glm::vec3(o.cropBox->min));
        u.v3("uCropMax", glm::vec3(o.cropBox->max));
    }

    u.f("uStepMm", caster.stepMm());
    u.f("uTermination", o.earlyTermination ? o.terminationTransmittance : 0.f);
    u.i("uPreintegrated", o.preintegrated ? 1 : 0);
    u.f("uBand", render::kClipFaceBandVoxels * caster.stepMm() / o.stepVoxels);
    u.f("uWeak", caster.weakGradient());
    u.v3("uBackground", o.background);

    u.i("uMode", shMode ? 2 : o.mode == render::Mode::Gradient ? 1 : 0);
    u.f("uEaAmbient", o.ambient);
    if (shMode) {
        // The lights as ShLights flattens them (none: the volumetric headlight, as the pipeline's
        // SH models get it).
        std::vector<std::shared_ptr<const lights::Light>> lights = o.lights;
        if (lights.empty())
            lights.push_back(render::headlight(camera, render::kVolumetricHeadlightIrradiance));
        const render::ShLights shl(sh.field->coefficients, lights, o.shWindow, o.shAmbient);
        u.i("uShCount", shl.coefficients());
        // Node-centred grid: texture coordinate (p/step + ½)/res (render/sh_field_grid.h). The
        // local field's grid (sh-global) has the same points: same volume, same rule.
        const render::ShFieldGrid& grid = *sh.field;
        glm::vec3 scale(0.f);
        for (int a = 0; a < 3; ++a)
            if (grid.step[a] > 0.f) scale[a] = 1.f / (grid.step[a] * float(grid.res[a]));
        u.v3("uShTexScale", scale);
        u.v3("uShTexOffset", 0.5f / glm::vec3(grid.res));
        for (int i = 0; i < shl.coefficients(); ++i) {
            u.v3(u.indexed("uShConstant", i).c_str(), shl.constants()[i]);
            u.f(u.indexed("uShWindow", i).c_str(), shl.window(i));
        }
        u.i("uShPointCount", int(shl.points().size()));
        for (int k = 0; k < int(shl.points().size()); ++k) {
            const render::ShLights::Point& p = shl.points()[std::size_t(k)];
            u.v3(u.indexed("uShPointPosition", k).c_str(), p.position);
            u.v3(u.indexed("uShPointIntensity", k).c_str(), p.intensity);
            u.f(u.indexed("uShPointMinDistance", k).c_str(), p.minDistance);
        }
        u.i("uShFaceCount", shBlend ? int(faces.size()) : 0);
        for (int f = 0; f < int(faces.size()); ++f) {
            u.v3(u.indexed("uShFacePoint", f).c_str(), glm::vec3(faces[std::size_t(f)].point));
            u.v3(u.indexed("uShFaceNormal", f).c_str(), glm::vec3(faces[std::size_t(f)].normal));
        }
        u.f("uShInvBand", setup.sh.cutBandMm > 0.f ? 1.f / setup.sh.cutBandMm : 0.f);
        // The near shadow (render/sh_shading.h ShLocalShader, ShGlobalShader): the directional
        // lights one by one, the rest summed, the spacing the local field's interpolation blends
        // (resampled beside sh-local's field, and beside sh-global's when its near factor is the
        // local field), the cut faces.
        const bool nearShadow = o.shNearShadow && !setup.sh.hierarchical && shSpacing != 0;
        u.i("uShNear", nearShadow ? 1 : 0);
        if (nearShadow) {
            for (int i = 0; i < shl.coefficients(); ++i)
                u.v3(u.indexed("uShSpread", i).c_str(), shl.spread()[i]);
            const auto& dirs = shl.directionals();
            u.i("uShDirCount", int(dirs.size()));
            for (int d = 0; d < int(dirs.size()); ++d) {
                u.v3(u.indexed("uShDirToward", d).c_str(), dirs[std::size_t(d)].toward);
                for (int i = 0; i < shl.coefficients(); ++i)
                    u.v3(u.indexed("uShDirCoeff", 16 * d + i).c_str(), dirs[std::size_t(d)].c[i]);
            }
            u.f("uShNearFactor", render::kNearShadowSpacings);
            u.f("uShNearTrace", o.shNearTraceVoxels);  // voxels at every level (near_trace)
            const float h = float(core::minComponent(setup.volume->geometry().spacing));
            u.f("uShH", h);
            // Exits this close are traced whole (render/sh_shading.h NearShadowTrace::wholeMm).
            u.f("uShWholeMm",
                setup.sh.local
                    ? std::min(render::kWholeReachVoxels, float(setup.sh.local->radiusVoxels())) * h
                    : 0.f);
            const std::vector<core::HalfSpace> cuts = render::lightCutFaces(o);
            u.i("uShCutCount", int(cuts.size()));
            for (int f = 0; f < int(cuts.size()); ++f) {
                u.v3(u.indexed("uShCutPoint", f).c_str(), glm::vec3(cuts[std::size_t(f)].point));
                u.v3(u.indexed("uShCutNormal", f).c_str(), glm::vec3(cuts[std::size_t(f)].normal));
            }
        }
    }
    if (o.mode == render::Mode::Gradient) {
        // The lights as the CPU shader flattens them (a scene without lights: the headlight).
        std::vector<std::shared_ptr<const lights::Light>> lights = o.lights;
        if (lights.empty()) lights.push_back(render::headlight(camera, 1.f));
        const render::BlinnPhongShader shader(o.blinnPhong, lights, o.irradianceSh);
        const auto& emitters = shader.emitters();
        u.f("uAmbient", o.blinnPhong.ambient);
        u.f("uDiffuse", o.blinnPhong.diffuse);
        u.f("uSpecular", o.blinnPhong.specular);
        u.f("uShininess", o.blinnPhong.shininess);
        u.i("uLightCount", int(emitters.size()));
        for (int k = 0; k < int(emitters.size()); ++k) {
            const auto& e = emitters[std::size_t(k)];
            u.i(u.indexed("uLightDirectional", k).c_str(), e.directional ? 1 : 0);
            u.i(u.indexed("uLightOneSided", k).c_str(), e.oneSided ? 1 : 0);
            u.v3(u.indexed("uLightToLight", k).c_str(), e.toLight);
            u.v3(u.indexed("uLightPosition", k).c_str(), e.position);
            u.v3(u.indexed("uLightValue", k).c_str(), e.value);
            u.f(u.indexed("uLightMinDistance", k).c_str(), e.minDistance);
            u.v3(u.indexed("uLightEmitterNormal", k).c_str(), e.emitterNormal);
        }
    }
    u.i("uVolume", 0);
    u.i("uJitter", 1);
    u.i("uTf", 2);
    u.i("uSkipDistance", 3);
    // SH fields on units 4–7, sh-global's local field on 8–11 (a unit without a texture of its
    // own gets the field's, never read: the shader reads ⌈C/4⌉ of them).
    for (int t = 0; t < 4; ++t) {
        u.i(u.indexed("uShField", t).c_str(), kShFieldUnit + t);
        u.i(u.indexed("uShLocal", t).c_str(), kShLocalUnit + t);
    }
    u.i("uShSpacing", kShSpacingUnit);

    // Save the state ImGui's renderer relies on that we change.
    GLint prevFbo = 0, prevProgram = 0, prevVao = 0, prevViewport[4] = {0, 0, 0, 0};
    glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &prevFbo);
    glGetIntegerv(GL_CURRENT_PROGRAM, &prevProgram);
    glGetIntegerv(GL_VERTEX_ARRAY_BINDING, &prevVao);
    glGetIntegerv(GL_VIEWPORT, prevViewport);
    const GLboolean blend = glIsEnabled(GL_BLEND), scissor = glIsEnabled(GL_SCISSOR_TEST);
    const GLboolean depth = glIsEnabled(GL_DEPTH_TEST), cull = glIsEnabled(GL_CULL_FACE);
    glDisable(GL_BLEND);
    glEnable(GL_SCISSOR_TEST);
    glScissor(rect.x, rect.y, rect.w, rect.h);
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_CULL_FACE);
    glViewport(0, 0, w, h);
    glBindVertexArray(vao_);

    // Pass 1: the ray caster into the float film.
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, filmFbo_);
    glUseProgram(raycast_);
    glBindTextureUnit(0, volumeTex_);
    glBindTextureUnit(1, jitterTex_);
    glBindTextureUnit(2, tfTex_);
    glBindTextureUnit(3, skipTex_);
    for (int t = 0; t < 4; ++t) {
        // Every sampler3D unit the program declares holds a 3D texture (an empty unit is
        // incomplete); the ones past the field's own are never read.
        const GLuint f = shField[t] ? shField[t] : shField[0] ? shField[0] : volumeTex_;
        const GLuint l = shLocal[t] ? shLocal[t] : f;
        glBindTextureUnit(GLuint(kShFieldUnit + t), f);
        glBindTextureUnit(GLuint(kShLocalUnit + t), l);
    }
    // The spacing's unit holds a 3D texture too (never read without the near shadow).
    glBindTextureUnit(GLuint(kShSpacingUnit), shSpacing    ? shSpacing
                                              : shField[0] ? shField[0]
                                                           : volumeTex_);
    if (rect.w > 0 && rect.h > 0) glDrawArrays(GL_TRIANGLES, 0, 3);

    // Pass 2: film → display bytes (the whole film).
    if (finish) {
        glDisable(GL_SCISSOR_TEST);
        const Uniforms d{display_};
        d.i("uFilm", 0);
        d.f("uExposureScale", std::exp2(exposureStops));
        d.i("uDisplay", display == render::Display::Clinical ? 0
                        : display == render::Display::Filmic ? 2
                                                             : 1);
        glBindFramebuffer(GL_DRAW_FRAMEBUFFER, displayFbo_);
        glUseProgram(display_);
        glBindTextureUnit(0, filmTex_);
        glDrawArrays(GL_TRIANGLES, 0, 3);
    }

    glBindTextureUnit(0, 0);
    glBindTextureUnit(1, 0);
    glBindTextureUnit(2, 0);
    glBindTextureUnit(3, 0);
    for (int t = 0; t < 4; ++t) {
        glBindTextureUnit(GLuint(kShFieldUnit + t), 0);
        glBindTextureUnit(GLuint(kShLocalUnit + t), 0);
    }
    glBindTextureUnit(GLuint(kShSpacingUnit), 0);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, GLuint(prevFbo));
    glUseProgram(GLuint(prevProgram));
    glBindVertexArray(GLuint(prevVao));
    glViewport(prevViewport[0], prevViewport[1], prevViewport[2], prevViewport[3]);
    if (blend) glEnable(GL_BLEND);
    if (scissor)
        glEnable(GL_SCISSOR_TEST);
    else
        glDisable(GL_SCISSOR_TEST);
    if (depth) glEnable(GL_DEPTH_TEST);
    if (cull) glEnable(GL_CULL_FACE);
    if (const std::string e = glErrorText(); !e.empty()) {
        why = "rendering with the GLSL ray caster: " + e;
        return false;
    }
    return true;
}

std::vector<std::uint8_t> GlRayCaster::readDisplay() const {
    std::vector<std::uint8_t> bytes(std::size_t(4) * width_ * height_);
    if (!displayTex_) return bytes;
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glGetTextureImage(displayTex_, 0, GL_RGBA, GL_UNSIGNED_BYTE, GLsizei(bytes.size()),
                      bytes.data());
    return bytes;
}

core::ImageRGBA GlRayCaster::readFilm() const {
    core::ImageRGBA img(std::max(filmW_, 1), std::max(filmH_, 1));
    if (!filmTex_) return img;
    glPixelStorei(GL_PACK_ALIGNMENT, 4);
    glGetTextureImage(filmTex_, 0, GL_RGBA, GL_FLOAT, GLsizei(img.pixels.size() * sizeof(float)),
                      img.pixels.data());
    return img;
}

}  // namespace voxlight::viewer
