// SPDX-License-Identifier: MIT
#include "visibility/multires_grid.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <ostream>
#include <queue>

#include "core/error.h"

namespace voxlight::visibility {

namespace {

/// Lowest finite physical value of a float volume (the stand-in for its non-finite voxels).
float lowestFinite(const core::Volume& volume) {
    float lo = std::numeric_limits<float>::infinity();
    volume.visit([&](const auto& v) {
        const std::size_t n = std::size_t(volume.voxelCount());
        for (std::size_t i = 0; i < n; ++i) {
            const float x = v.slope * float(v.data[i]) + v.intercept;
            if (std::isfinite(x)) lo = std::min(lo, x);
        }
    });
    return std::isfinite(lo) ? lo : 0.f;
}

/// CIE L*u*v* (D65 white, Y_n = 1) of a linear sRGB colour.
glm::vec3 linearRgbToLuv(const glm::vec3& c) {
    const double X = 0.4124 * c.r + 0.3576 * c.g + 0.1805 * c.b;
    const double Y = 0.2126 * c.r + 0.7152 * c.g + 0.0722 * c.b;
    const double Z = 0.0193 * c.r + 0.1192 * c.g + 0.9505 * c.b;
    constexpr double kUn = 0.19784, kVn = 0.46834;  // u', v' of D65
    const double L = Y > 0.008856 ? 116.0 * std::cbrt(Y) - 16.0 : 903.3 * Y;
    const double d = X + 15.0 * Y + 3.0 * Z;
    if (!(d > 0.0)) return {float(L), 0.f, 0.f};
    const double u = 4.0 * X / d, v = 9.0 * Y / d;
    return {float(L), float(13.0 * L * (u - kUn)), float(13.0 * L * (v - kVn))};
}

}  // namespace

glm::ivec3 BlockPyramid::blockCoord(std::size_t index) const {
    const std::size_t bx = std::size_t(blocks_.x), by = std::size_t(blocks_.y);
    return {int(index % bx), int((index / bx) % by), int(index / (bx * by))};
}

BlockPyramid::FlatView BlockPyramid::flatVoxels() const {
    std::call_once(flat_->once, [&] {
        const glm::ivec3 d = dims();
        const std::size_t sy = std::size_t(d.x), sz = std::size_t(d.x) * std::size_t(d.y);
        const std::size_t n = sz * std::size_t(d.z);
        // Row by row from each block's level 0 (x fastest there too).
        auto forRows = [&](auto&& row) {
            tbb::parallel_for(0, d.z, [&](int z) {
                for (int y = 0; y < d.y; ++y)
                    for (int bx = 0; bx < blocks_.x; ++bx) {
                        const float* src = data(blockIndex(bx, y / kBlockSize, z / kBlockSize), 0) +
                                           kBlockSize * (std::size_t(y % kBlockSize) +
                                                         kBlockSize * std::size_t(z % kBlockSize));
                        const int x0 = bx * kBlockSize;
                        row(src, std::min(kBlockSize, d.x - x0),
                            std::size_t(x0) + sy * std::size_t(y) + sz * std::size_t(z));
                    }
            });
        };
        std::atomic<bool> integral{true};
        forRows([&](const float* src, int count, std::size_t) {
            for (int k = 0; k < count; ++k)
                if (!(src[k] >= -32768.f && src[k] <= 32767.f && src[k] == std::nearbyint(src[k])))
                    integral.store(false, std::memory_order_relaxed);
        });
        // Not zero-filled: every element is written below, in parallel (a value-initialised
        // array zeroed the whole copy on one thread first, page faults included).
        if (integral.load()) {
            std::unique_ptr<std::int16_t[]> flat(new std::int16_t[n]);
            forRows([&](const float* src, int count, std::size_t at) {
                for (int k = 0; k < count; ++k) flat[at + std::size_t(k)] = std::int16_t(src[k]);
            });
            flat_->small = std::move(flat);
            flat_->bytes = n * sizeof(std::int16_t);
        } else {
            std::unique_ptr<float[]> flat(new float[n]);
            forRows([&](const float* src, int count, std::size_t at) {
                std::copy_n(src, count, flat.get() + at);
            });
            flat_->voxels = std::move(flat);
            flat_->bytes = n * sizeof(float);
        }
    });
    return {flat_->voxels.get(), flat_->small.get()};
}

BlockPyramid BlockPyramid::build(const core::Volume& volume, const core::Progress& progress) {
    VL_CHECK(!volume.empty());
    BlockPyramid p;
    p.geometry_ = volume.geometry();
    const glm::ivec3 d = volume.dims();
    p.blocks_ = (d + (kBlockSize - 1)) / kBlockSize;
    const std::size_t count = std::size_t(p.blocks_.x) * p.blocks_.y * p.blocks_.z;
    p.stats_.resize(count);
    p.data_.resize(count * kPyramidFloats);
    const bool mayBeNonFinite =
        volume.type() == core::VoxelType::Float32 && volume.countNonFinite() > 0;
    const float substitute = mayBeNonFinite ? lowestFinite(volume) : 0.f;
    progress.report("block pyramid", 0.0);
    volume.visit([&](const auto& v) {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 8), [&](const auto& range) {
            for (std::size_t b = range.begin(); b != range.end(); ++b) {
                const glm::ivec3 bc = p.blockCoord(b);
                float* level0 = p.data_.data() + b * kPyramidFloats;
                // Level 0: the voxels, the edge voxel repeated past the volume's end.
                BlockStats& st = p.stats_[b];
                float lo = std::numeric_limits<float>::infinity(), hi = -lo;
                for (int k = 0; k < kBlockSize; ++k)
                    for (int j = 0; j < kBlockSize; ++j)
                        for (int i = 0; i < kBlockSize; ++i) {
                            const int x = std::min(bc.x * kBlockSize + i, d.x - 1);
                            const int y = std::min(bc.y * kBlockSize + j, d.y - 1);
                            const int z = std::min(bc.z * kBlockSize + k, d.z - 1);
                            float val = v.at(x, y, z);
                            if (!std::isfinite(val)) val = substitute;
                            level0[i + kBlockSize * (j + kBlockSize * k)] = val;
                            lo = std::min(lo, val);
                            hi = std::max(hi, val);
                        }
                // Levels 1..4: means of 2×2×2 samples of the level below (= box means of s³
                // voxels, as every level halves exactly).
                for (int l = 1; l < kLevels; ++l) {
                    const int n = levelResolution(l), m = 2 * n;
                    const float* src = level0 + levelOffset(l - 1);
                    float* dst = level0 + levelOffset(l);
                    for (int k = 0; k < n; ++k)
                        for (int j = 0; j < n; ++j)
                            for (int i = 0; i < n; ++i) {
                                double s = 0.0;
                                for (int c = 0; c < 8; ++c)
                                    s += src[(2 * i + (c & 1)) + m * ((2 * j + ((c >> 1) & 1)) +
                                                                      m * (2 * k + (c >> 2)))];
                                dst[i + n * (j + n * k)] = float(s / 8.0);
                            }
                }
                // Range and histogram over the owned voxels (a padded copy counts once).
                st.min = lo;
                st.max = hi;
                st.mean = level0[levelOffset(kLevels - 1)];
                st.histogram.fill(0);
                // In double: hi − lo overflows float for data near ±3.4e38, and (val − lo)·0
                // was NaN, a negative bin (a crash found by a hostile-input probe).
                const double scale =
                    hi > lo ? double(kHistogramBins) / (double(hi) - double(lo)) : 0.0;
                const glm::ivec3 own = glm::min(glm::ivec3(kBlockSize), d - bc * kBlockSize);
                for (int k = 0; k < own.z; ++k)
                    for (int j = 0; j < own.y; ++j)
                        for (int i = 0; i < own.x; ++i) {
                            const float val = level0[i + kBlockSize * (j + kBlockSize * k)];
                            const int bin = std::clamp(int((double(val) - double(lo)) * scale), 0,
                                                       kHistogramBins - 1);
                            ++st.histogram[std::size_t(bin)];
                        }
            }
        });
    });
    // Cell ranges from the voxels (with the substitute for non-finite ones).
    p.cells_ = (d + (BlockPyramid::kCellVoxels - 1)) / BlockPyramid::kCellVoxels;
    const glm::ivec3 nc = p.cells_;
    p.cellRange_.resize(std::size_t(nc.x) * nc.y * nc.z);
    volume.visit([&](const auto& v) {
        tbb::parallel_for(tbb::blocked_range<int>(0, nc.z), [&](const auto& range) {
            constexpr int c4 = BlockPyramid::kCellVoxels;
            for (int cz = range.begin(); cz != range.end(); ++cz)
                for (int cy = 0; cy < nc.y; ++cy)
                    for (int cx = 0; cx < nc.x; ++cx) {
                        float lo = std::numeric_limits<float>::infinity(), hi = -lo;
                        for (int z = cz * c4; z <= std::min(cz * c4 + c4, d.z - 1); ++z)
                            for (int y = cy * c4; y <= std::min(cy * c4 + c4, d.y - 1); ++y)
                                for (int x = cx * c4; x <= std::min(cx * c4 + c4, d.x - 1); ++x) {
                                    float val = v.at(x, y, z);
                                    if (!std::isfinite(val)) val = substitute;
                                    lo = std::min(lo, val);
                                    hi = std::max(hi, val);
                                }
                        p.cellRange_[std::size_t(cx) +
                                     std::size_t(nc.x) * (cy + std::size_t(nc.y) * cz)] = {lo, hi};
                    }
        });
    });
    progress.report("block pyramid", 1.0);
    return p;
}

LodBudget LodBudget::fromReduction(double ratio, std::uint64_t voxels) {
    if (!(ratio >= 1.0) || !std::isfinite(ratio))
        throw InputError("lod budget", "data_reduction", "must be a finite ratio ≥ 1",
                         "give e.g. 8 for one sample per 8 voxels");
    return {std::uint64_t(double(voxels) / ratio)};
}

LodBudget LodBudget::fromBytes(double bytes, double bytesPerPoint) {
    if (!(bytes > 0.0) || !std::isfinite(bytes) || !(bytesPerPoint > 0.0))
        throw InputError("lod budget", "bytes", "must be a finite size > 0", "give e.g. 64 MB");
    return {std::uint64_t(bytes / bytesPerPoint)};
}

std::vector<float> blockSignificance(const BlockPyramid& pyramid,
                                     const optics::TransferFunction& tf,
                                     const optics::TfTable& table) {
    const double h = core::minComponent(pyramid.geometry().spacing);
    const float leak = table.cellWidth();
    auto colour = [&](float value) {
        const optics::TfSample s = table.lookup(value);
        const float alpha = float(1.0 - std::exp(-double(s.extinction) * h));
        return linearRgbToLuv(alpha * (s.albedo + s.emission));
    };
    std::vector<float> sig(pyramid.blockCount());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, sig.size(), 64), [&](const auto& range) {
        for (std::size_t b = range.begin(); b != range.end(); ++b) {
            const BlockStats& st = pyramid.stats(b);
            if (tf.transparentOver(st.min - leak, st.max + leak)) {
                sig[b] = -1.f;
                continue;
            }
            const glm::vec3 mean = colour(st.mean);
            double total = 0.0, sum = 0.0;
            const double width = (double(st.max) - double(st.min)) / kHistogramBins;
            for (int j = 0; j < kHistogramBins; ++j) {
                const std::uint32_t c = st.histogram[std::size_t(j)];
                if (c == 0) continue;
                const float centre = float(st.min + (j + 0.5) * width);
                sum += double(c) * glm::length(colour(centre) - mean);
                total += double(c);
            }
            sig[b] = total > 0.0 ? float(sum / total) : 0.f;
        }
    });
    return sig;
}

LodSelection selectLod(const BlockPyramid& pyramid, const optics::TransferFunction& tf,
                       const optics::TfTable& table, const LodBudget& budget) {
    LodSelection s;
    s.significance = blockSignificance(pyramid, tf, table);
    s.cellVisible = visibleCells(pyramid, tf, table);
    const std::size_t count = pyramid.blockCount();
    // A block whose own voxels are transparent is still stored when a visible cell overlaps its
    // owned extent: trilinear samples inside it read its neighbours' voxels one voxel past its
    // faces (a dense surface on a block face), and visibility must be stored there.
    {
        constexpr int kCellsPerBlock = kBlockSize / BlockPyramid::kCellVoxels;
        const glm::ivec3 cells = pyramid.cells();
        for (std::size_t b = 0; b < count; ++b) {
            if (s.significance[b] >= 0.f) continue;
            const glm::ivec3 bc = pyramid.blockCoord(b);
            const glm::ivec3 lo = glm::max(bc * kCellsPerBlock - 1, glm::ivec3(0));
            const glm::ivec3 hi = glm::min(bc * kCellsPerBlock + kCellsPerBlock - 1, cells - 1);
            bool apron = false;
            for (int z = lo.z; z <= hi.z && !apron; ++z)
                for (int y = lo.y; y <= hi.y && !apron; ++y)
                    for (int x = lo.x; x <= hi.x && !apron; ++x)
                        apron =
                            s.cellVisible[std::size_t(x) + std::size_t(cells.x) *
                                                               (y + std::size_t(cells.y) * z)] != 0;
            if (apron) s.significance[b] = 0.f;
        }
    }
    s.level.assign(count, std::int8_t(kNone));
    // Start: every visible block at 1³.
    for (std::size_t b = 0; b < count; ++b)
        if (s.significance[b] >= 0.f) {
            s.level[b] = std::int8_t(kLevels - 1);
            s.points += 1;
        } else {
            s.significance[b] = 0.f;
        }
    s.budgetPoints = std::max(budget.maxPoints, s.points);
    // Refine by gain per sample (see header): the distortion model gains S/4 per level.
    struct Entry {
        double priority;
        std::uint32_t block;
        bool operator<(const Entry& o) const {
            return priority < o.priority || (priority == o.priority && block > o.block);
        }
    };
    auto cost = [](int level) {  // samples added by refining from `level` to level − 1
        const std::uint64_t a = std::uint64_t(levelResolution(level - 1)),
                            b = std::uint64_t(levelResolution(level));
        return a * a * a - b * b * b;
    };
    auto priority = [&](std::size_t b) {
        const double gain = std::max(double(s.significance[b]) / 4.0, kZeroSignificanceGain);
        return gain / double(cost(s.level[b]));
    };
    std::priority_queue<Entry> queue;
    for (std::size_t b = 0; b < count; ++b)
        if (s.level[b] != kNone) queue.push({priority(b), std::uint32_t(b)});
    while (!queue.empty()) {
        const Entry e = queue.top();
        queue.pop();
        const std::uint64_t c = cost(s.level[e.block]);
        if (s.points + c > s.budgetPoints) continue;  // too dear now, and only dearer later
        s.points += c;
        --s.level[e.block];
        if (s.level[e.block] > 0) queue.push({priority(e.block), e.block});
    }
    for (std::size_t b = 0; b < count; ++b)
        ++s.blocksPerLevel[s.level[b] == kNone ? kLevels : std::size_t(s.level[b])];
    return s;
}

std::vector<std::uint8_t> visibleCells(const BlockPyramid& pyramid,
                                       const optics::TransferFunction& tf,
                                       const optics::TfTable& table) {
    const float leak = table.cellWidth();
    std::vector<std::uint8_t> visible(pyramid.cellCount());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, visible.size(), 4096),
                      [&](const auto& range) {
                          for (std::size_t c = range.begin(); c != range.end(); ++c) {
                              const auto& r = pyramid.cellRange(c);
                              visible[c] = !tf.transparentOver(r[0] - leak, r[1] + leak);
                          }
                      });
    return visible;
}

std::ostream& operator<<(std::ostream& os, const LodSelection& s) {
    os << "LodSelection{points=" << s.points << "/" << s.budgetPoints
       << ", blocks 16^3/8^3/4^3/2^3/1^3/none=";
    for (int l = 0; l <= kLevels; ++l) os << (l ? "/" : "") << s.blocksPerLevel[std::size_t(l)];
    return os << "}";
}

VisibleCellCounts::VisibleCellCounts(const glm::ivec3& cells,
                                     const std::vector<std::uint8_t>& visible)
    : cells_(cells) {
    VL_CHECK(visible.empty() ||
             visible.size() == std::size_t(cells.x) * std::size_t(cells.y) * std::size_t(cells.z));
    const std::size_t sx = std::size_t(cells.x) + 1, sxy = sx * (std::size_t(cells.y) + 1);
    sum_.assign(sxy * (std::size_t(cells.z) + 1), 0u);
    for (int z = 1; z <= cells.z; ++z)
        for (int y = 1; y <= cells.y; ++y) {
            std::uint32_t row = 0;  // visible cells of this row up to x
            for (int x = 1; x <= cells.x; ++x) {
                row += visible.empty() ? 1u
                                       : visible[std::size_t(x - 1) +
                                                 std::size_t(cells.x) *
                                                     (std::size_t(y - 1) +
                                                      std::size_t(cells.y) * std::size_t(z - 1))];
                const std::size_t i = std::size_t(x) + sx * std::size_t(y) + sxy * std::size_t(z);
                sum_[i] = row + sum_[i - sx] + sum_[i - sxy] - sum_[i - sx - sxy];
            }
        }
}

MultiresGrid::MultiresGrid(std::shared_ptr<const BlockPyramid> pyramid, LodSelection selection)
    : pyramid_(std::move(pyramid)), selection_(std::move(selection)) {
    VL_CHECK(pyramid_ != nullptr);
    VL_CHECK_EQ(selection_.level.size(), pyramid_->blockCount());
    if (selection_.cellVisible.empty()) selection_.cellVisible.assign(pyramid_->cellCount(), 1);
    VL_CHECK_EQ(selection_.cellVisible.size(), pyramid_->cellCount());
    visibleCounts_ = VisibleCellCounts(pyramid_->cells(), selection_.cellVisible);
    const glm::ivec3 nb = blocks();
    hi_ = glm::vec3(dims() - 1);
    last_ = nb - 1;
    stride_ = glm::ivec3(1, nb.x, nb.x * nb.y);
    levelData_.assign(selection_.level.size(), nullptr);
    for (std::size_t b = 0; b < levelData_.size(); ++b)
        if (selection_.level[b] != kNone) levelData_[b] = pyramid_->data(b, selection_.level[b]);
    // Ramp lengths per face (header comment): g = (s_b + s_c)/2 toward the stored face
    // neighbour c (s_b where it is not stored), and per diagonal neighbour n on that side the
    // limit (s_b + s_n)/2 where it is shorter. Isolated blocks: neither they nor a neighbour are
    // stored.
    const std::size_t count = selection_.level.size();
    ramp_.assign(count * 6, 1.f);
    invRamp_.assign(count * 6, 1.f);
    diagonalRamp_.assign(count * 6 * 8, 0.f);
    limited_.assign(count * 6, 0);
    isolated_.assign(count, 1);
    auto spacingAt = [&](const glm::ivec3& n) {  // 0: outside the volume or not stored
        if (glm::any(glm::lessThan(n, glm::ivec3(0))) || glm::any(glm::greaterThanEqual(n, nb)))
            return 0;
        const int l = selection_.level[pyramid_->blockIndex(n.x, n.y, n.z)];
        return l == kNone ? 0 : levelSpacing(l);
    };
    for (std::size_t b = 0; b < count; ++b) {
        const glm::ivec3 c = pyramid_->blockCoord(b);
        for (int dz = -1; dz <= 1 && isolated_[b]; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx)
                    if (spacingAt(c + glm::ivec3(dx, dy, dz)) > 0) isolated_[b] = 0;
        if (selection_.level[b] == kNone) continue;
        const int sb = levelSpacing(selection_.level[b]);
        for (int face = 0; face < 6; ++face) {
            const int a = face / 2, a1 = (a + 1) % 3, a2 = (a + 2) % 3;
            glm::ivec3 d(0);
            d[a] = face % 2 ? 1 : -1;
            const int sc = spacingAt(c + d);
            const float g = sc > 0 ? 0.5f * float(sb + sc) : float(sb);
            ramp_[b * 6 + std::size_t(face)] = g;
            invRamp_[b * 6 + std::size_t(face)] = 1.f / g;
            for (int k = 0; k < 8; ++k) {
                const glm::ivec2 o = diagonalOffset(k);
                d[a1] = o.x;
                d[a2] = o.y;
                const int sn = spacingAt(c + d);
                const float limit = sn > 0 ? 0.5f * float(sb + sn) : g;
                diagonalRamp_[(b * 6 + std::size_t(face)) * 8 + std::size_t(k)] = limit;
                if (limit < g) limited_[b * 6 + std::size_t(face)] |= std::uint8_t(1u << k);
            }
        }
    }
    // Per face: can a diagonal neighbour n across it reach into the block's sample box on that
    // axis? Only where n's own ramp back across the axis, g_n toward m = n's neighbour in this
    // block's slab, exceeds (s_n + s_b)/2 (m coarser than b, or not stored): n's limit from b
    // fades in only past n's box on the other axes.
    reachesIn_.assign(count * 6, 0);
    for (std::size_t b = 0; b < count; ++b) {
        if (selection_.level[b] == kNone) continue;
        const glm::ivec3 c = pyramid_->blockCoord(b);
        const int sb = levelSpacing(selection_.level[b]);
        for (int face = 0; face < 6; ++face) {
            const int a = face / 2, a1 = (a + 1) % 3, a2 = (a + 2) % 3;
            const int side = face % 2 ? 1 : -1;
            for (int k = 0; k < 8 && !reachesIn_[b * 6 + std::size_t(face)]; ++k) {
                const glm::ivec2 o = diagonalOffset(k);
                glm::ivec3 m = c;
                m[a1] += o.x;
                m[a2] += o.y;
                glm::ivec3 n = m;
                n[a] += side;
                const int sn = spacingAt(n), sm = spacingAt(m);
                if (sn == 0) continue;
                const float gn = sm > 0 ? 0.5f * float(sn + sm) : float(sn);
                if (gn > 0.5f * float(sn + sb)) reachesIn_[b * 6 + std::size_t(face)] = 1;
            }
        }
    }
}

float MultiresGrid::rampLength(std::size_t block, int face, const glm::vec3& pastBox) const {
    const std::size_t f = block * 6 + std::size_t(face);
    const float g = ramp_[f];
    const int a = face / 2, a1 = (a + 1) % 3, a2 = (a + 2) % 3;
    float length = g;
    for (unsigned mask = limited_[f]; mask != 0; mask &= mask - 1) {
        const int k = std::countr_zero(mask);
        const float limit = diagonalRamp_[f * 8 + std::size_t(k)];
        // How far p lies toward n on n's other axes, over the gap to n's box there: 0 within the
        // block's box on such an axis, 1 from n's box on (product over the axes n is off on).
        const glm::ivec2 o = diagonalOffset(k);
        float t = 1.f;
        if (o.x != 0) t *= std::min(1.f, std::max(0.f, float(o.x) * pastBox[a1]) / limit);
        if (o.y != 0) t *= std::min(1.f, std::max(0.f, float(o.y) * pastBox[a2]) / limit);
        length = std::min(length, g + t * (limit - g));
    }
    return length;
}

glm::vec3 MultiresGrid::samplePosition(std::size_t block, int level, int i, int j, int k) const {
    const glm::ivec3 b = pyramid_->blockCoord(block);
    const float s = float(levelSpacing(level));
    return glm::vec3(b * kBlockSize) + (glm::vec3(i, j, k) + 0.5f) * s - 0.5f;
}

void MultiresGrid::weights(const glm::vec3& pIn, BlockWeights& out) const {
    const glm::ivec3& d = dims();
    const glm::ivec3& nb = blocks();
    glm::vec3 p;
    for (int a = 0; a < 3; ++a) p[a] = std::min(std::max(pIn[a], 0.f), float(d[a] - 1));
    out.count = 0;
    // The owner's coordinates directly (blockCoord(owner) would divide three times per sample).
    const glm::ivec3 oc = ownerCoord(p);
    const std::size_t owner = indexOf(oc);
    if (isolated_[owner]) return;
    // Inside the owner's sample box on every axis only the owner contributes (header comment):
    // the fast path. Inside it on one axis, the blocks across that axis contribute only where
    // reachesIn_ says a diagonal one can (its ramp toward the owner's neighbour in the owner's
    // slab reaches past the owner's box face); otherwise their column is not visited.
    bool inside[3] = {false, false, false};
    if (const int l = selection_.level[owner]; l != kNone) {
        glm::vec3 lo, hi;
        sampleBox(oc, l, lo, hi);
        for (int a = 0; a < 3; ++a) inside[a] = p[a] >= lo[a] && p[a] <= hi[a];
        if (inside[0] && inside[1] && inside[2]) {  // ownerAlone()'s case
            out.count = 1;
            out.block[0] = std::uint32_t(owner);
            out.weight[0] = 1.f;
            out.level[0] = std::int8_t(l);
            out.local[0] = (p - glm::vec3(oc * kBlockSize) + 0.5f) * levelInvSpacing(l) - 0.5f;
            return;
        }
    }
    // Candidates: per axis the owner's column and, unless pruned above, the neighbouring column
    // on p's side of the owner's centre (no ramp reaches farther than 8 voxels past its block's
    // face).
    int col[3][2];
    for (int a = 0; a < 3; ++a) {
        col[a][0] = oc[a];
        const int other = p[a] < float(oc[a] * kBlockSize) + 7.5f ? oc[a] - 1 : oc[a] + 1;
        const bool reaches =
            !inside[a] || reachesIn_[owner * 6 + std::size_t(2 * a + (other > oc[a]))];
        col[a][1] = reaches && other >= 0 && other < nb[a] ? other : -1;
    }
    float sum = 0.f;
    for (int c = 0; c < 8; ++c) {
        const int x = col[0][c & 1], y = col[1][(c >> 1) & 1], z = col[2][c >> 2];
        if (x < 0 || y < 0 || z < 0) continue;
        const std::size_t idx = pyramid_->blockIndex(x, y, z);
        const int l = selection_.level[idx];
        if (l == kNone) continue;
        // Signed voxels past the sample box per axis (+ past the top, − below the bottom, 0
        // inside); the faces with a fixed ramp length first (one multiply each), so a block out
        // of reach is left before any limited face's length is worked out.
        const float s = float(levelSpacing(l));
        const glm::vec3 boxLo = glm::vec3(x, y, z) * float(kBlockSize) + (0.5f * s - 0.5f);
        const glm::vec3 boxHi = boxLo + (float(kBlockSize) - s);
        glm::vec3 past;
        for (int a = 0; a < 3; ++a)
            past[a] = p[a] > boxHi[a] ? p[a] - boxHi[a] : p[a] < boxLo[a] ? p[a] - boxLo[a] : 0.f;
        float w = 1.f;
        int limitedAxes = 0;
        for (int a = 0; a < 3; ++a) {
            if (past[a] == 0.f) continue;
            const std::size_t f = idx * 6 + std::size_t(2 * a + (past[a] > 0.f));
            if (limited_[f])
                limitedAxes |= 1 << a;
            else
                w *= std::max(0.f, 1.f - std::abs(past[a]) * invRamp_[f]);
        }
        for (int a = 0; a < 3 && limitedAxes != 0 && w > 0.f; ++a)
            if (limitedAxes & (1 << a))
                w *= std::max(
                    0.f, 1.f - std::abs(past[a]) / rampLength(idx, 2 * a + (past[a] > 0.f), past));
        if (!(w > 0.f)) continue;
        const int n = levelResolution(l);
        glm::vec3 u =
            (p - boxLo) * levelInvSpacing(l);  // sample coordinates: the box is [0, n − 1]
        u = glm::min(glm::max(u, glm::vec3(0.f)), glm::vec3(float(n - 1)));
        const int k = out.count++;
        out.block[k] = std::uint32_t(idx);
        out.weight[k] = w;
        out.level[k] = std::int8_t(l);
        out.local[k] = u;
        sum += w;
    }
    if (out.count == 0) return;
    const float inv = 1.f / sum;
    for (int k = 0; k < out.count; ++k) out.weight[k] *= inv;
}

float MultiresGrid::sampleBlend(const glm::vec3& p, float empty) const {
    BlockWeights w;
    weights(p, w);
    if (w.count == 0) return empty;
    float v = 0.f;
    for (int k = 0; k < w.count; ++k)
        addTrilinear(levelData_[w.block[k]], levelResolution(w.level[k]), 1, w.local[k],
                     w.weight[k], &v);
    return v;
}

}  // namespace voxlight::visibility
