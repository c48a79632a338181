// SPDX-License-Identifier: MIT
#include "viewer/volume_summary.h"

#include <algorithm>
#include <cmath>

namespace voxlight::viewer {

VolumeSummary summarize(const core::Volume& volume) {
    VolumeSummary s;
    const core::Geometry& g = volume.geometry();
    s.description = volume.description;
    s.format = volume.format;
    s.type = std::string(core::toString(volume.type()));
    s.modality = std::string(core::toString(volume.modality));
    s.unit = volume.mapping.unit;
    s.orientation = g.orientationCode();
    s.dims = g.dims;
    s.spacing = g.spacing;
    s.origin = g.origin;
    s.extent = g.extent();
    s.range = volume.physicalRange();
    s.warnings = volume.warnings;
    return s;
}

std::vector<float> Histogram::logNormalized() const {
    std::vector<float> out(counts.size(), 0.f);
    std::uint64_t peak = 0;
    for (auto c : counts) peak = std::max(peak, c);
    if (peak == 0) return out;
    const double norm = std::log1p(double(peak));
    for (std::size_t i = 0; i < counts.size(); ++i)
        out[i] = float(std::log1p(double(counts[i])) / norm);
    return out;
}

Histogram histogram(const core::Volume& volume, const std::array<double, 2>& range, int bins,
                    const core::Progress& progress) {
    Histogram h;
    h.lo = range[0];
    h.hi = range[1] > range[0] ? range[1] : range[0] + 1.0;
    h.counts.assign(std::size_t(std::max(bins, 1)), 0);
    const glm::ivec3 d = volume.dims();
    // Regular sub-lattice: stride n along each axis keeps about kHistogramFullScan voxels.
    int stride = 1;
    while (volume.voxelCount() / (std::uint64_t(stride) * stride * stride) > kHistogramFullScan)
        ++stride;
    const double scale = double(h.counts.size()) / (h.hi - h.lo);
    const int last = int(h.counts.size()) - 1;
    for (int k = 0; k < d.z; k += stride) {
        progress.report("histogram", double(k) / d.z);
        for (int j = 0; j < d.y; j += stride)
            for (int i = 0; i < d.x; i += stride) {
                const float v = volume.at(i, j, k);
                if (!std::isfinite(v)) continue;
                const int b = std::clamp(int((double(v) - h.lo) * scale), 0, last);
                ++h.counts[std::size_t(b)];
                ++h.total;
            }
    }
    return h;
}

}  // namespace voxlight::viewer
