// SPDX-License-Identifier: MIT
#pragma once
// Reading JSON input with precise errors: a value with its dotted key path (Field), typed accessors
// that throw an InputError naming the file and the key, unknown keys refused with a "did you
// mean". The scene reader's, shared by every JSON input (scenes, sessions, sweeps).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.h"

namespace voxlight::io {

/// "a number", "an object", ... for messages.
std::string typeName(const nlohmann::json& j);
/// The value as compact JSON, cut to 40 characters (bytes that are not UTF-8 replaced).
std::string shortDump(const nlohmann::json& j);
/// A number as written (the shortest text that reads back as it: "got 170" for 170.0000001 hid
/// why it was refused); a non-finite one (built in code) as "nan"/"inf", not JSON's "null".
std::string numberAsWritten(const nlohmann::json& j);
/// "a string \"abc\"", "an array [1,2]", "null": what a value is, for "got …" in messages.
inline std::string described(const nlohmann::json& j) {
    return j.is_null() ? "null" : typeName(j) + " " + shortDump(j);
}
/// Levenshtein distance, for "did you mean" suggestions.
std::size_t editDistance(const std::string& a, const std::string& b);

/// A JSON value with its dotted key path, for typed access with precise errors.
class Field {
  public:
    Field(const nlohmann::json& j, std::string path, const std::string& source)
        : j_(j), path_(std::move(path)), source_(source) {}

    const nlohmann::json& raw() const { return j_; }
    const std::string& path() const { return path_; }
    [[noreturn]] void fail(const std::string& problem, const std::string& fix = {}) const {
        throw InputError(source_, path_, problem, fix);
    }
    bool isObject() const { return j_.is_object(); }
    bool isString() const { return j_.is_string(); }
    bool isArray() const { return j_.is_array(); }

    void expectObject() const {
        if (!j_.is_object()) fail("must be an object, got " + described(j_));
    }
    /// Rejects keys not in `allowed`, suggesting the nearest one.
    void allowOnly(const std::vector<std::string>& allowed) const {
        expectObject();
        for (auto it = j_.begin(); it != j_.end(); ++it) {
            if (std::find(allowed.begin(), allowed.end(), it.key()) != allowed.end()) continue;
            std::string best;
            std::size_t bestD = 3;
            for (const auto& a : allowed)
                if (std::size_t d = editDistance(it.key(), a); d < bestD) best = a, bestD = d;
            throw InputError(source_, child(it.key()).path_, "unknown key",
                             best.empty() ? "allowed keys: " + joinNames(allowed)
                                          : "did you mean '" + best + "'?");
        }
    }
    bool has(const std::string& key) const { return j_.is_object() && j_.contains(key); }
    Field child(const std::string& key) const {
        static const nlohmann::json null;
        return Field(has(key) ? j_.at(key) : null, path_.empty() ? key : path_ + "." + key,
                     source_);
    }
    Field at(std::size_t i) const {
        return Field(j_.at(i), path_ + "[" + std::to_string(i) + "]", source_);
    }
    std::size_t size() const { return j_.size(); }

    double number(double lo = -HUGE_VAL, double hi = HUGE_VAL) const {
        if (!j_.is_number()) fail("must be a number, got " + described(j_));
        const double v = j_.get<double>();
        if (!std::isfinite(v) || v < lo || v > hi) {
            std::ostringstream os;
            os << "must be in [" << lo << ", " << hi << "], got " << numberAsWritten(j_);
            fail(os.str());
        }
        return v;
    }
    int integer(int lo, int hi) const {
        // A whole number written as 1e9 or 16.0 is an integer (JSON has one number type); its
        // range says whether it fits.
        if (j_.is_number_float() && std::isfinite(j_.get<double>()) &&
            j_.get<double>() == std::floor(j_.get<double>())) {
            const double v = j_.get<double>();
            if (v < lo || v > hi)
                fail("must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) +
                     "], got " + numberAsWritten(j_));
            return int(v);
        }
        if (!j_.is_number_integer() && !j_.is_number_unsigned())
            fail("must be an integer, got " + described(j_));
        // Unsigned values beyond long long (up to 2^64-1) would wrap to negatives in the message.
        if (j_.is_number_unsigned() &&
            j_.get<std::uint64_t>() > std::uint64_t(std::numeric_limits<long long>::max()))
            fail("must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) +
                 "], got " + std::to_string(j_.get<std::uint64_t>()));
        const long long v = j_.get<long long>();
        if (v < lo || v > hi)
            fail("must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) +
                 "], got " + std::to_string(v));
        return int(v);
    }
    std::string string() const {
        if (!j_.is_string()) fail("must be a string, got " + described(j_));
        return j_.get<std::string>();
    }
    bool boolean(const std::string& fix = "write true or false, without quotes") const {
        if (!j_.is_boolean()) fail("must be true or false, got " + described(j_), fix);
        return j_.get<bool>();
    }
    std::string oneOf(const std::vector<std::string>& allowed) const {
        const std::string s = string();
        if (std::find(allowed.begin(), allowed.end(), s) == allowed.end())
            fail("'" + s + "' is not allowed", "choose one of: " + joinNames(allowed));
        return s;
    }
    glm::dvec3 vec3(double lo = -HUGE_VAL, double hi = HUGE_VAL) const {
        if (!j_.is_array() || j_.size() != 3)
            fail("must be an array of 3 numbers, got " + described(j_));
        glm::dvec3 v;
        for (int i = 0; i < 3; ++i) v[i] = at(std::size_t(i)).number(lo, hi);
        return v;
    }
    glm::dvec3 unitVec3() const {
        const glm::dvec3 v = vec3();
        // Scaled by the largest component first: [1e200, 0, 0] is a direction too (its length
        // overflowed to ∞, and v/∞ read as the zero vector).
        const double largest = std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)});
        if (!(largest > 0.0)) fail("must be a non-zero direction, got [0, 0, 0]");
        const glm::dvec3 u = v / largest;
        return u / glm::length(u);
    }

    // Optional accessors: keep the default when the key is absent.
    void get(const std::string& k, double& out, double lo = -HUGE_VAL, double hi = HUGE_VAL) const {
        if (has(k)) out = child(k).number(lo, hi);
    }
    void get(const std::string& k, int& out, int lo, int hi) const {
        if (has(k)) out = child(k).integer(lo, hi);
    }
    void get(const std::string& k, glm::dvec3& out, double lo = -HUGE_VAL,
             double hi = HUGE_VAL) const {
        if (has(k)) out = child(k).vec3(lo, hi);
    }
    void get(const std::string& k, bool& out, const std::string& fix) const {
        if (has(k)) out = child(k).boolean(fix);
    }
    void getDirection(const std::string& k, glm::dvec3& out) const {
        if (has(k)) out = child(k).unitVec3();
    }
    void get(const std::string& k, std::string& out,
             const std::vector<std::string>& allowed) const {
        if (has(k)) out = child(k).oneOf(allowed);
    }

  private:
    const nlohmann::json& j_;
    std::string path_;
    const std::string& source_;
};

}  // namespace voxlight::io
