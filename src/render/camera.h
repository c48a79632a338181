// SPDX-License-Identifier: MIT
#pragma once
// Pinhole (perspective) and orthographic cameras in world millimetres (patient LPS).
//
// Orbit parameters: the eye sits at target + distance · (sin az · cos el, −cos az · cos el,
// sin el), so azimuth 0, elevation 0 looks from the patient's front (anterior, −y) toward posterior
// with superior (+z) up and the patient's left on the image's right (the radiological anterior
// view); azimuth 90° looks from the patient's left. Positive roll turns the image
// counter-clockwise. Explicit look-at (eye, target, up) is used when `eye` is set. Pixel (x, y) has
// its centre at (x + 0.5, y + 0.5); row 0 is the top of the image.
//
// Fitting (orbit cameras with distance 0, orthographic ones with ortho_height 0): the camera frames
// a set of world points (the hull of the visible matter) tightly in the image plane — the view
// direction stays the orbit's, the eye moves (sideways and back) until the points' projection
// fills 1 − 2·margin of the limiting image dimension, centred. With an explicit target only the
// distance (or ortho height) is fitted, symmetric about the target. This frames what the view
// shows, not a bounding sphere of the grid (which left objects at 42–65 % of the image width).
#include <glm/glm.hpp>
#include <iosfwd>
#include <optional>
#include <span>

namespace voxlight::render {

enum class Projection { Perspective, Orthographic };

struct CameraSpec {
    Projection projection = Projection::Perspective;
    double azimuthDeg = 30.0, elevationDeg = 20.0, rollDeg = 0.0;
    double distance = 0.0;             ///< mm from the target; 0 = fit the points in view
    double fovYDeg = 30.0;             ///< perspective: vertical field of view, (0, 180)
    double orthoHeight = 0.0;          ///< orthographic: view height in mm; 0 = fit
    std::optional<glm::dvec3> target;  ///< default: centre of the bounds
    std::optional<glm::dvec3> eye;     ///< set → look-at
    glm::dvec3 up{0.0, 0.0, 1.0};
    /// Fitting: fraction of the limiting image dimension left empty on each side, [0, 0.45].
    double margin = 0.05;
};

struct Ray {
    glm::dvec3 origin;
    glm::dvec3 direction;  ///< unit
};

/// |cos| between spec.up and the view direction above which up counts as parallel (within 2.6°:
/// closer, the image's up would swing with every small change of view).
inline constexpr double kParallelUpCos = 0.999;

class Camera {
  public:
    /// Frames `spec` around the world-space box [boundsMin, boundsMax] (its eight corners are the
    /// fit points). Throws InputError (source "camera", field "image size") on a size < 1.
    Camera(const CameraSpec& spec, const glm::dvec3& boundsMin, const glm::dvec3& boundsMax,
           int width, int height);
    /// Frames `spec` around `fitPoints` (world mm, at least one; their bounding-box centre is the
    /// default target). Same errors.
    Camera(const CameraSpec& spec, std::span<const glm::dvec3> fitPoints, int width, int height);

    Ray generate(int x, int y) const;
    /// The ray through continuous pixel coordinates (px, py) ∈ [0, width) × [0, height) (pixel
    /// (x, y)'s centre is (x + 0.5, y + 0.5)): for sub-pixel samples.
    Ray generateAt(double px, double py) const;
    /// Thin lens (depth of field, the path tracer's): lens diameter and the distance of the plane
    /// in focus, both mm, the plane perpendicular to forward(). Aperture 0 = pinhole.
    void setLens(double apertureMm, double focusMm);
    double aperture() const { return aperture_; }
    double focusDistance() const { return focus_; }
    /// generateAt's ray, but leaving from the lens point (u1, u2) ∈ [0,1)² (concentric disk
    /// mapping) towards where the pinhole ray meets the plane in focus; generateAt's ray when the
    /// aperture is 0.
    Ray generateThroughLens(double px, double py, double u1, double u2) const;
    /// Inverse of generate(): the continuous pixel coordinates (x, y) of world point p, so that
    /// the ray of pixel (i, j) passes through p exactly when p projects to (i, j). False when p is
    /// not in front of a perspective camera (depth along forward() ≤ 0), where nothing is returned.
    bool project(const glm::dvec3& p, double& x, double& y) const;
    /// The map behind project(), affine in p: X = dot(x, p) + x0, Y = …, W = …; the pixel
    /// coordinates are X / W, Y / W, and W is the depth along forward() (perspective, in front
    /// when W > 0) or 1 (orthographic). For projecting many points (boxes of cells).
    struct ProjectiveMap {
        glm::dvec3 x{0.0}, y{0.0}, w{0.0};
        double x0 = 0.0, y0 = 0.0, w0 = 1.0;
    };
    ProjectiveMap projectiveMap() const;
    /// generateAt()'s per-pixel constants, for evaluators outside this class (the viewer's GLSL
    /// ray caster): sx = px·pixelScale.x − 1, sy = 1 − py·pixelScale.y; a perspective ray leaves
    /// eye() along normalize(forward() + sx·rightStep + sy·upStep), an orthographic one leaves
    /// eye() + sx·rightStep + sy·upStep along forward().
    struct PixelMap {
        glm::dvec2 pixelScale{1.0};
        glm::dvec3 rightStep{0.0}, upStep{0.0};
    };
    PixelMap pixelMap() const { return {{pixelScaleX_, pixelScaleY_}, rightStep_, upStep_}; }
    int width() const { return width_; }
    int height() const { return height_; }
    const glm::dvec3& eye() const { return eye_; }
    const glm::dvec3& forward() const { return forward_; }
    const glm::dvec3& right() const { return right_; }
    const glm::dvec3& up() const { return up_; }
    Projection projection() const { return projection_; }
    /// True when spec.up was (nearly) parallel to the view direction and a world axis replaced it
    /// (up() says which); never a NaN basis.
    bool upReplaced() const { return upReplaced_; }
    /// Perspective: vertical field of view in radians. Orthographic: view height in mm.
    double fovY() const { return fovY_; }
    double orthoHeight() const { return orthoHeight_; }

  private:
    void fit(const CameraSpec& spec, std::span<const glm::dvec3> points, double aspect);
    bool upReplaced_ = false;
    Projection projection_;
    glm::dvec3 eye_, forward_, right_, up_;
    double fovY_ = 0.5, tanHalf_ = 0.27, orthoHeight_ = 1.0;
    int width_ = 1, height_ = 1;
    // generate()'s per-pixel constants: 2/width, 2/height, and right/up scaled to one unit of the
    // normalised image coordinate (image-plane half-extent at unit distance, or in mm for ortho).
    double pixelScaleX_ = 1.0, pixelScaleY_ = 1.0;
    double aperture_ = 0.0, focus_ = 1.0;
    glm::dvec3 rightStep_{0.0}, upStep_{0.0};
};
std::ostream& operator<<(std::ostream& os, const Camera& c);

}  // namespace voxlight::render
