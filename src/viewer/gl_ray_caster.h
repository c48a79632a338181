// SPDX-License-Identifier: MIT
#pragma once
// The viewer's GLSL ray caster: shaders/raycast.frag (embedded at build time) evaluates the CPU
// ray caster's emission–absorption and gradient (Blinn–Phong) modes and its SH visibility
// shading (sh-local, sh-global, ritschel: render/sh_shading.h) from the same inputs —
// pipeline::CasterSetup: the volume as a 3D texture (R16 for integer voxels, R32F for float),
// the TF's pre-integration table as a 2D texture of its nodes and cumulative integrals, the skip
// cells' skip distances as a 3D texture (empty-space skipping), the same step, opacity, lights,
// clip planes, crop box, early termination and per-pixel jitter, and the pipeline's fitted camera
// — plus, for the SH methods, the visibility fields resampled as RGBA16F 3D textures
// (viewer/sh_grids.h; uploaded once per field, the last kKeptShFields kept, so a switch between
// sh-local and sh-global uploads nothing again) and the lights' SH as uniforms (point lights
// evaluated per sample, as ShLights::shade does) — into a float film, then shaders/display.frag maps it to 8 bits as
// the CLI's PNG is mapped (exposure, display transform). The image stays in a texture for the
// window to draw; readDisplay()/readFilm() read it back (tests, screenshots).
//
// Needs a current OpenGL 4.5 context for every call but the constructor. GL errors never throw
// or abort: init() and render() return false with one line saying why, and the viewer shows the
// CPU image instead. Which scenes it can do at all: viewer/gl_support.h.
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "core/image.h"
#include "pipeline/pipeline.h"
#include "render/tonemap.h"
#include "viewer/sh_grids.h"

namespace voxlight::viewer {

class GlRayCaster {
  public:
    GlRayCaster() = default;
    ~GlRayCaster();  ///< deletes its GL objects (the context must still be current)
    GlRayCaster(const GlRayCaster&) = delete;
    GlRayCaster& operator=(const GlRayCaster&) = delete;

    /// Checks the context (OpenGL ≥ 4.5) and compiles the shaders; false with the reason (the
    /// GL version, or the compiler's first message) otherwise.
    bool init(std::string& why);
    bool ready() const { return raycast_ != 0; }
    /// The renderer string of the context (e.g. "llvmpipe (LLVM 15.0.6, 256 bits)").
    const std::string& glRenderer() const { return renderer_; }

    /// Renders `setup` (glUnsupportedReason() empty) at its camera's size into texture().
    /// Uploads the volume, the TF table and the jitter only when they changed since the last
    /// call. Does not wait for the GPU (glFinish() for timing). False with the reason on failure
    /// (volume larger than the GL's 3D textures, out of memory, a GL error).
    /// Which pixels a render() computes: all, a kWarmUpPixels² corner (uploads, and the first draw
    /// that makes a GL compile the shader's machine code — which a timing must not include), or
    /// the central half of each side (a quarter of the pixels, where the volume is: a cheap probe
    /// of the frame's cost that over- rather than underestimates it).
    enum class Scope { Full, WarmUp, CentreQuarter };
    /// `sh`: the SH methods' resampled fields (RenderedImage::shGrids); ignored by the others.
    bool render(const pipeline::CasterSetup& setup, const ShGrids& sh, float exposureStops,
                render::Display display, std::string& why, Scope scope = Scope::Full);
    /// What upload() did: nothing was left to upload (Ready), some was (Progress: call again
    /// until Ready), or the GL failed (Failed, with the reason as render() would give it).
    enum class Upload { Ready, Progress, Failed };
    /// Uploads, for about `seconds` of work, part of what render() of `setup` needs and the GL
    /// does not hold yet — the volume, then the SH fields (the large textures), a slab of
    /// z-slices at a time — so that a UI can spread a new volume's upload over its frames (a
    /// 256³ volume and its fields take a few hundred ms on llvmpipe). render() uploads whatever
    /// is left itself, and the small tables (TF, skip cells, jitter) always.
    Upload upload(const pipeline::CasterSetup& setup, const ShGrids& sh, double seconds,
                  std::string& why);
    /// A slice of a frame, for a GL too slow to render one between two UI frames: texel rows
    /// [rowBegin, rowEnd) of the film only (every pixel as render() computes it: the same image
    /// in any number of slices); with `finish`, then the whole film into texture(). Until then
    /// texture() keeps the last finished image (and its size).
    bool renderRows(const pipeline::CasterSetup& setup, const ShGrids& sh, float exposureStops,
                    render::Display display, std::string& why, int rowBegin, int rowEnd,
                    bool finish);
    /// The same for texels [x0, x0 + w) × [y0, y0 + h) of the film (clamped to it).
    bool renderRect(const pipeline::CasterSetup& setup, const ShGrids& sh, float exposureStops,
                    render::Display display, std::string& why, int x0, int y0, int w, int h,
                    bool finish);
    /// SH field grids uploaded as textures so far (tests: once per field, not per frame).
    std::size_t shUploads() const { return shUploads_; }
    static constexpr std::size_t kKeptShFields = 4;
    static constexpr int kWarmUpPixels = 8;
    /// The display image (RGBA8, row 0 = the image's top); 0 before the first render.
    unsigned texture() const { return displayTex_; }
    int width() const { return width_; }
    int height() const { return height_; }
    /// texture()'s pixels, 4 bytes each, row 0 = the image's top.
    std::vector<std::uint8_t> readDisplay() const;
    /// The linear film (radiance + T·background, alpha = coverage), row 0 = the image's top.
    core::ImageRGBA readFilm() const;

  private:
    static constexpr double kUploadAll = std::numeric_limits<double>::infinity();
    /// The volume's texture from z-slice volumeZ_ on, for about `seconds`.
    Upload uploadVolume(const std::shared_ptr<const core::Volume>& volume, double seconds,
                        std::string& why);
    void uploadTable(const optics::TfTable& table);
    void uploadSkipCells(const grid::BrickMajorants& cells);
    void uploadJitter(int width, int height, bool jitter, std::uint64_t seed);
    struct Rect {
        int x, y, w, h;  ///< texels (GL's scissor box)
    };
    bool draw(const pipeline::CasterSetup& setup, const ShGrids& sh, float exposureStops,
              render::Display display, std::string& why, const Rect& rect, bool finish);
    bool ensureTarget(unsigned& tex, unsigned& fbo, unsigned format, int width, int height,
                      std::string& why);
    bool ensureFilm(int width, int height, std::string& why);
    bool ensureDisplay(int width, int height, std::string& why);
    /// The textures of `grid` into out[0..4) (0 past its own), made the most recently used;
    /// uploads what is left of them for about `seconds`.
    /// `spacing`: the grid's spacing texture (ShFieldGrid::spacing; 0 without one).
    Upload shTextures(const std::shared_ptr<const render::ShFieldGrid>& grid, unsigned out[4],
                      double seconds, std::string& why, unsigned* spacing = nullptr);
    void release();

    std::string renderer_;
    unsigned raycast_ = 0, display_ = 0, vao_ = 0;
    unsigned volumeTex_ = 0, tfTex_ = 0, jitterTex_ = 0, skipTex_ = 0;
    unsigned filmTex_ = 0, displayTex_ = 0, filmFbo_ = 0, displayFbo_ = 0;
    int width_ = 0, height_ = 0;  ///< the display texture's
    int filmW_ = 0, filmH_ = 0;
    // What is uploaded (held, so that a pointer is never that of a newer object).
    std::shared_ptr<const core::Volume> volume_;
    std::shared_ptr<const core::Volume> volumePending_;  ///< being uploaded: slices [0, volumeZ_)
    int volumeZ_ = 0;
    std::shared_ptr<const optics::TfTable> table_;
    std::shared_ptr<const grid::BrickMajorants> skipCells_;
    float valueScale_ = 1.f, valueOffset_ = 0.f;
    struct ShUpload {
        std::shared_ptr<const render::ShFieldGrid> grid;
        unsigned textures[5] = {0, 0, 0, 0, 0};  ///< the coefficients', then the spacing's
        int texture = 0, z = 0;  ///< the upload's progress: textures before `texture` are full
    };
    std::vector<ShUpload> shUploaded_;  ///< most recently used first
    std::size_t shUploads_ = 0;
    int jitterW_ = 0, jitterH_ = 0;
    bool jitterOn_ = false;
    std::uint64_t jitterSeed_ = 0;
};

}  // namespace voxlight::viewer
