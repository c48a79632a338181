// SPDX-License-Identifier: MIT
#include "render/camera.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <ostream>

#include "core/error.h"

namespace voxlight::render {

namespace {
constexpr double kDegToRad = 3.14159265358979323846 / 180.0;
/// Smallest radius a fitted set of points counts as (mm): a single point still gets a camera.
constexpr double kMinFitRadius = 1e-3;
/// The fitted eye stays this fraction of the points' radius in front of the nearest one.
constexpr double kNearGap = 1e-3;
/// Margins above this leave less than a tenth of the image for the object.
constexpr double kMaxFitMargin = 0.45;
}  // namespace

namespace {
std::array<glm::dvec3, 8> boxCorners(const glm::dvec3& lo, const glm::dvec3& hi) {
    std::array<glm::dvec3, 8> c;
    for (int i = 0; i < 8; ++i)
        c[i] = glm::dvec3((i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z);
    return c;
}
}  // namespace

Camera::Camera(const CameraSpec& spec, const glm::dvec3& boundsMin, const glm::dvec3& boundsMax,
               int width, int height)
    : Camera(spec, boxCorners(boundsMin, boundsMax), width, height) {}

Camera::Camera(const CameraSpec& spec, std::span<const glm::dvec3> points, int width, int height)
    : projection_(spec.projection), width_(width), height_(height) {
    if (width < 1 || height < 1) throw InputError("camera", "image size", "must be at least 1x1");
    VL_CHECK(!points.empty());
    glm::dvec3 lo(INFINITY), hi(-INFINITY);
    for (const glm::dvec3& p : points) lo = glm::min(lo, p), hi = glm::max(hi, p);
    const glm::dvec3 centre = 0.5 * (lo + hi);
    const glm::dvec3 target = spec.target.value_or(centre);
    fovY_ = spec.fovYDeg * kDegToRad;
    tanHalf_ = std::tan(0.5 * fovY_);
    const double aspect = double(width) / double(height);
    // Orientation first (it does not depend on where the eye ends up), then placement.
    glm::dvec3 up = spec.up, orbitDir(0.0);
    if (spec.eye) {
        eye_ = *spec.eye;
        // The scene checks an eye against an explicit target; the default target (the visible
        // matter's centre) is known only here.
        const glm::dvec3 toTarget = target - eye_;
        const double largest =
            std::max({std::abs(toTarget.x), std::abs(toTarget.y), std::abs(toTarget.z)});
        if (!(largest > 1e-9))
            throw InputError("camera", "camera.eye",
                             "coincides with the target (without camera.target: the centre of "
                             "the visible matter)",
                             "move camera.eye away from it, or set camera.target");
        forward_ = glm::normalize(toTarget / largest);
    } else {
        const double az = spec.azimuthDeg * kDegToRad, el = spec.elevationDeg * kDegToRad;
        orbitDir =
            glm::dvec3(std::sin(az) * std::cos(el), -std::cos(az) * std::cos(el), std::sin(el));
        forward_ = -orbitDir;
    }
    // Looking (nearly) along `up` leaves the image's up undefined: take the first world axis that
    // is not (posterior/anterior first, as for a top view with the default up = superior).
    if (std::abs(glm::dot(glm::normalize(up), forward_)) > kParallelUpCos) {
        const glm::dvec3 candidates[] = {glm::dvec3(0.0, forward_.z > 0 ? 1.0 : -1.0, 0.0),
                                         glm::dvec3(0.0, 0.0, 1.0), glm::dvec3(1.0, 0.0, 0.0)};
        for (const glm::dvec3& c : candidates)
            if (std::abs(glm::dot(c, forward_)) <= kParallelUpCos) {
                up = c;
                break;
            }
        upReplaced_ = true;
    }
    right_ = glm::normalize(glm::cross(forward_, up));
    up_ = glm::cross(right_, forward_);
    if (spec.rollDeg != 0.0) {
        const double r = spec.rollDeg * kDegToRad, c = std::cos(r), s = std::sin(r);
        const glm::dvec3 r2 = c * right_ + s * up_, u2 = -s * right_ + c * up_;
        right_ = r2;
        up_ = u2;
    }
    fit(spec, points, aspect);
    pixelScaleX_ = 2.0 / width_;
    pixelScaleY_ = 2.0 / height_;
    const double h = projection_ == Projection::Perspective ? tanHalf_ : 0.5 * orthoHeight_;
    rightStep_ = (h * aspect) * right_;
    upStep_ = h * up_;
}

void Camera::fit(const CameraSpec& spec, std::span<const glm::dvec3> points, double aspect) {
    // Work in the camera's frame about O (the target, or the points' box centre): x right, y up,
    // z forward. The eye goes to O + ex·right + ey·up + ez·forward.
    glm::dvec3 lo(INFINITY), hi(-INFINITY);
    for (const glm::dvec3& p : points) lo = glm::min(lo, p), hi = glm::max(hi, p);
    const glm::dvec3 origin = spec.target.value_or(0.5 * (lo + hi));
    const double radius = std::max(0.5 * glm::length(hi - lo), kMinFitRadius);
    const double fill = 1.0 - 2.0 * std::clamp(spec.margin, 0.0, kMaxFitMargin);
    // An explicit target (or look-at) stays in the centre.
    const bool centred = spec.target.has_value() || spec.eye.has_value();
    double ex = 0.0, ey = 0.0, ez = 0.0, zMin = INFINITY;
    for (const glm::dvec3& p : points) zMin = std::min(zMin, glm::dot(p - origin, forward_));
    if (projection_ == Projection::Perspective) {
        // Frustum side planes of slope t (tangent of the half-angle times the fill): a point fits
        // when |x − ex| ≤ t·(z − ez). Without a target the tightest eye on each axis is where both
        // side planes touch the points: with A = max(x − t·z), B = min(x + t·z), ex = (A + B)/2
        // and ez = (B − A)/(2t); the nearer-limited axis wins (the smaller ez) and the other stays
        // centred at its own midpoint, which does not depend on ez.
        const double tx = tanHalf_ * aspect * fill, ty = tanHalf_ * fill;
        double ax = -INFINITY, bx = INFINITY, ay = -INFINITY, by = INFINITY, d = 0.0;
        for (const glm::dvec3& p : points) {
            const glm::dvec3 q = p - origin;
            const double x = glm::dot(q, right_), y = glm::dot(q, up_), z = glm::dot(q, forward_);
            ax = std::max(ax, x - tx * z), bx = std::min(bx, x + tx * z);
            ay = std::max(ay, y - ty * z), by = std::min(by, y + ty * z);
            d = std::max(d, std::max(std::abs(x) / tx, std::abs(y) / ty) - z);
        }
        if (spec.eye) {
            return;  // placed by the scene
        } else if (spec.distance > 0.0) {
            ez = -spec.distance;
        } else if (centred) {
            ez = -d;
        } else {
            ex = 0.5 * (ax + bx), ey = 0.5 * (ay + by);
            ez = std::min((bx - ax) / (2.0 * tx), (by - ay) / (2.0 * ty));
        }
        // Never inside or level with the nearest point (a single point, or a flat view).
        if (spec.distance <= 0.0) ez = std::min(ez, zMin - kNearGap * radius);
        orthoHeight_ = 2.0 * radius;
    } else {
        double xLo = INFINITY, xHi = -INFINITY, yLo = INFINITY, yHi = -INFINITY;
        for (const glm::dvec3& p : points) {
            const glm::dvec3 q = p - origin;
            const double x = glm::dot(q, right_), y = glm::dot(q, up_);
            xLo = std::min(xLo, x), xHi = std::max(xHi, x);
            yLo = std::min(yLo, y), yHi = std::max(yHi, y);
        }
        double halfX = 0.0, halfY = 0.0;
        if (centred || spec.orthoHeight > 0.0) {
            halfX = std::max(-xLo, xHi), halfY = std::max(-yLo, yHi);
        } else {
            ex = 0.5 * (xLo + xHi), ey = 0.5 * (yLo + yHi);
            halfX = 0.5 * (xHi - xLo), halfY = 0.5 * (yHi - yLo);
        }
        orthoHeight_ = spec.orthoHeight > 0.0
                           ? spec.orthoHeight
                           : std::max(2.0 * std::max(halfY, halfX / aspect) / fill, kMinFitRadius);
        if (spec.eye) return;
        // Rays start on the eye's plane: put it behind every point.
        ez = spec.distance > 0.0 ? -spec.distance : zMin - radius;
    }
    eye_ = origin + ex * right_ + ey * up_ + ez * forward_;
}

Ray Camera::generate(int x, int y) const { return generateAt(x + 0.5, y + 0.5); }

Ray Camera::generateAt(double px, double py) const {
    const double sx = px * pixelScaleX_ - 1.0;  // −1 left … +1 right
    const double sy = 1.0 - py * pixelScaleY_;  // +1 top … −1 bottom
    Ray r;
    if (projection_ == Projection::Perspective) {
        const glm::dvec3 d = forward_ + sx * rightStep_ + sy * upStep_;
        r.origin = eye_;
        r.direction = d * (1.0 / std::sqrt(glm::dot(d, d)));
    } else {
        r.origin = eye_ + sx * rightStep_ + sy * upStep_;
        r.direction = forward_;
    }
    return r;
}

void Camera::setLens(double apertureMm, double focusMm) {
    if (!(apertureMm >= 0.0) || !std::isfinite(apertureMm))
        throw InputError("camera", "aperture", "must be a finite diameter >= 0 mm");
    if (apertureMm > 0.0 && !(focusMm > 0.0 && std::isfinite(focusMm)))
        throw InputError("camera", "focus_distance", "must be a finite distance > 0 mm");
    aperture_ = apertureMm;
    focus_ = apertureMm > 0.0 ? focusMm : 1.0;
}

Ray Camera::generateThroughLens(double px, double py, double u1, double u2) const {
    Ray r = generateAt(px, py);
    if (!(aperture_ > 0.0)) return r;
    // Where this pixel's pinhole ray meets the plane in focus: every lens point aims there.
    const glm::dvec3 focusPoint =
        projection_ == Projection::Perspective
            ? r.origin + r.direction * (focus_ / glm::dot(r.direction, forward_))
            : r.origin + forward_ * focus_;
    // Concentric mapping of the unit square onto the unit disk (Shirley & Chiu 1997): uniform
    // in area, continuous, so stratified samples stay stratified.
    const double a = 2.0 * u1 - 1.0, b = 2.0 * u2 - 1.0;
    double dx = 0.0, dy = 0.0;
    if (a != 0.0 || b != 0.0) {
        constexpr double kQuarterPi = 0.25 * std::numbers::pi;
        const bool wide = std::abs(a) > std::abs(b);
        const double radius = wide ? a : b;
        const double phi = wide ? kQuarterPi * (b / a) : 2.0 * kQuarterPi - kQuarterPi * (a / b);
        dx = radius * std::cos(phi), dy = radius * std::sin(phi);
    }
    r.origin += 0.5 * aperture_ * (dx * right_ + dy * up_);
    r.direction = glm::normalize(focusPoint - r.origin);
    return r;
}

Camera::ProjectiveMap Camera::projectiveMap() const {
    // generate() builds d = forward + sx·rightStep + sy·upStep with the three mutually orthogonal,
    // and pixel x = (sx + 1) / pixelScaleX − ½, y = (1 − sy) / pixelScaleY − ½. For p − eye = λ·d
    // (perspective) λ is the depth W, and sx·W = (p − eye)·rightStep / |rightStep|².
    const glm::dvec3 rx = rightStep_ / (glm::dot(rightStep_, rightStep_) * pixelScaleX_);
    const glm::dvec3 ry = -upStep_ / (glm::dot(upStep_, upStep_) * pixelScaleY_);
    const double cx = 1.0 / pixelScaleX_ - 0.5, cy = 1.0 / pixelScaleY_ - 0.5;
    ProjectiveMap m;
    if (projection_ == Projection::Perspective) {
        m.x = rx + cx * forward_;
        m.y = ry + cy * forward_;
        m.w = forward_;
        m.x0 = -glm::dot(m.x, eye_);
        m.y0 = -glm::dot(m.y, eye_);
        m.w0 = -glm::dot(m.w, eye_);
    } else {
        m.x = rx;
        m.y = ry;
        m.x0 = cx - glm::dot(rx, eye_);
        m.y0 = cy - glm::dot(ry, eye_);
    }
    return m;
}

bool Camera::project(const glm::dvec3& p, double& x, double& y) const {
    const ProjectiveMap m = projectiveMap();
    const double w = glm::dot(m.w, p) + m.w0;
    if (!(w > 0.0)) return false;
    x = (glm::dot(m.x, p) + m.x0) / w;
    y = (glm::dot(m.y, p) + m.y0) / w;
    return true;
}

std::ostream& operator<<(std::ostream& os, const Camera& c) {
    return os << "Camera{" << (c.projection() == Projection::Perspective ? "perspective" : "ortho")
              << " eye (" << c.eye().x << ", " << c.eye().y << ", " << c.eye().z << ") forward ("
              << c.forward().x << ", " << c.forward().y << ", " << c.forward().z << ") "
              << c.width() << "x" << c.height() << "}";
}

}  // namespace voxlight::render
