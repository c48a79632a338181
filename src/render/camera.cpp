// SPDX-License-Identifier: MIT
#include "render/camera.h"

#include <cmath>
#include <ostream>

#include "core/error.h"

namespace voxlight::render {

namespace {
constexpr double kDegToRad = 3.14159265358979323846 / 180.0;
}

Camera::Camera(const CameraSpec& spec, const glm::dvec3& boundsMin, const glm::dvec3& boundsMax,
               int width, int height)
    : projection_(spec.projection), width_(width), height_(height) {
    if (width < 1 || height < 1) throw InputError("camera", "image size", "must be at least 1x1");
    const glm::dvec3 centre = 0.5 * (boundsMin + boundsMax);
    const double radius = std::max(0.5 * glm::length(boundsMax - boundsMin), 1e-3);
    const glm::dvec3 target = spec.target.value_or(centre);
    fovY_ = spec.fovYDeg * kDegToRad;
    tanHalf_ = std::tan(0.5 * fovY_);
    const double aspect = double(width) / double(height);
    // Fit: the bounding sphere fills the smaller image dimension.
    const double fitTan = tanHalf_ * std::min(1.0, aspect);
    const double fitDistance = radius / std::sin(std::atan(fitTan)) * 1.02;
    glm::dvec3 up = spec.up;
    if (spec.eye) {
        eye_ = *spec.eye;
    } else {
        const double az = spec.azimuthDeg * kDegToRad, el = spec.elevationDeg * kDegToRad;
        const glm::dvec3 dir(std::sin(az) * std::cos(el), -std::cos(az) * std::cos(el),
                             std::sin(el));
        const double d = spec.distance > 0.0 ? spec.distance : fitDistance;
        eye_ = target + d * dir;
    }
    forward_ = glm::normalize(target - eye_);
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
    orthoHeight_ =
        spec.orthoHeight > 0.0 ? spec.orthoHeight : 2.04 * radius / std::min(1.0, aspect);
    pixelScaleX_ = 2.0 / width_;
    pixelScaleY_ = 2.0 / height_;
    const double h = projection_ == Projection::Perspective ? tanHalf_ : 0.5 * orthoHeight_;
    rightStep_ = (h * aspect) * right_;
    upStep_ = h * up_;
}

Ray Camera::generate(int x, int y) const {
    const double sx = (x + 0.5) * pixelScaleX_ - 1.0;  // −1 left … +1 right
    const double sy = 1.0 - (y + 0.5) * pixelScaleY_;  // +1 top … −1 bottom
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
