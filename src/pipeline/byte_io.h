// SPDX-License-Identifier: MIT
#pragma once
// Bounded binary encoding of cache artifacts: little-endian PODs and length-prefixed arrays. A
// ByteReader never reads past its buffer: a short or inconsistent payload throws CacheFormatError,
// which the cache turns into "recompute", never into a crash or a half-read artifact.
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

namespace voxlight::pipeline {

/// A cache payload that cannot be decoded (truncated, wrong sizes, values out of range).
class CacheFormatError : public std::runtime_error {
  public:
    using std::runtime_error::runtime_error;
};

class ByteWriter {
  public:
    template <class T>
    void pod(const T& v) {
        static_assert(std::is_trivially_copyable_v<T>);
        const auto* p = reinterpret_cast<const unsigned char*>(&v);
        bytes_.insert(bytes_.end(), p, p + sizeof(T));
    }
    template <class T>
    void array(const std::vector<T>& v) {
        static_assert(std::is_trivially_copyable_v<T>);
        pod(std::uint64_t(v.size()));
        const auto* p = reinterpret_cast<const unsigned char*>(v.data());
        bytes_.insert(bytes_.end(), p, p + v.size() * sizeof(T));
    }
    void string(const std::string& s) {
        pod(std::uint64_t(s.size()));
        bytes_.insert(bytes_.end(), s.begin(), s.end());
    }
    const std::vector<unsigned char>& bytes() const { return bytes_; }
    std::vector<unsigned char>& bytes() { return bytes_; }

  private:
    std::vector<unsigned char> bytes_;
};

class ByteReader {
  public:
    ByteReader(const unsigned char* data, std::size_t size) : p_(data), end_(data + size) {}
    template <class T>
    T pod() {
        static_assert(std::is_trivially_copyable_v<T>);
        need(sizeof(T));
        T v;
        std::memcpy(&v, p_, sizeof(T));
        p_ += sizeof(T);
        return v;
    }
    /// An array of at most maxCount elements (guards the allocation against a damaged length).
    template <class T>
    std::vector<T> array(std::uint64_t maxCount) {
        const auto n = pod<std::uint64_t>();
        if (n > maxCount || n > remaining() / (sizeof(T) ? sizeof(T) : 1))
            throw CacheFormatError("array length " + std::to_string(n) + " does not fit");
        std::vector<T> v(static_cast<std::size_t>(n));
        if (n) std::memcpy(v.data(), p_, std::size_t(n) * sizeof(T));
        p_ += std::size_t(n) * sizeof(T);
        return v;
    }
    std::string string(std::uint64_t maxLength = 1 << 20) {
        const auto n = pod<std::uint64_t>();
        if (n > maxLength || n > remaining()) throw CacheFormatError("string length does not fit");
        std::string s(reinterpret_cast<const char*>(p_), std::size_t(n));
        p_ += n;
        return s;
    }
    std::size_t remaining() const { return std::size_t(end_ - p_); }
    /// The payload must be consumed exactly.
    void expectEnd() const {
        if (p_ != end_) throw CacheFormatError(std::to_string(remaining()) + " trailing bytes");
    }

  private:
    void need(std::size_t n) const {
        if (remaining() < n) throw CacheFormatError("payload ends early");
    }
    const unsigned char* p_;
    const unsigned char* end_;
};

}  // namespace voxlight::pipeline
