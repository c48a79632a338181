// SPDX-License-Identifier: MIT
#include "core/error.h"

#include "core/text.h"

namespace voxlight {

std::string oneLine(const std::string& text) {
    std::string out;
    out.reserve(text.size());
    for (std::size_t i = 0; i < text.size();) {
        const auto c = static_cast<unsigned char>(text[i]);
        if (c >= 0x20 && c < 0x7f) {
            out += char(c);
            ++i;
            continue;
        }
        const std::size_t n = c >= 0xc2 && c <= 0xdf   ? 2
                              : c >= 0xe0 && c <= 0xef ? 3
                              : c >= 0xf0 && c <= 0xf4 ? 4
                                                       : 0;
        bool ok = n > 0 && i + n <= text.size();
        for (std::size_t k = 1; ok && k < n; ++k)
            ok = (static_cast<unsigned char>(text[i + k]) & 0xc0) == 0x80;
        if (ok && n >= 3) {  // no overlong forms, surrogates or code points beyond U+10FFFF
            const auto d = static_cast<unsigned char>(text[i + 1]);
            ok = !((c == 0xe0 && d < 0xa0) || (c == 0xed && d >= 0xa0) || (c == 0xf0 && d < 0x90) ||
                   (c == 0xf4 && d >= 0x90));
        }
        if (ok) {
            out.append(text, i, n);
            i += n;
            continue;
        }
        static const char* kHex = "0123456789ABCDEF";
        out += "\\x";
        out += kHex[c >> 4];
        out += kHex[c & 15];
        ++i;
    }
    return out;
}

namespace {
std::string composeMessage(const std::string& source, const std::string& field,
                           const std::string& problem, const std::string& fix) {
    std::string msg = source.empty() ? std::string() : source + ": ";
    if (!field.empty()) msg += field + ": ";
    msg += problem;
    if (!fix.empty()) msg += " (" + fix + ")";
    return oneLine(msg);
}
}  // namespace

InputError::InputError(std::string source, std::string field, std::string problem, std::string fix)
    : std::runtime_error(composeMessage(source, field, problem, fix)),
      source_(std::move(source)),
      field_(std::move(field)),
      problem_(std::move(problem)),
      fix_(std::move(fix)) {}

std::string joinNames(const std::vector<std::string>& names) {
    std::string s;
    for (const auto& n : names) s += (s.empty() ? "" : ", ") + n;
    return s;
}

namespace detail {
void checkFailed(const char* expr, const char* file, int line, const std::string& values) {
    std::ostringstream os;
    os << "internal check failed: " << expr << " at " << file << ":" << line;
    if (!values.empty()) os << " (" << values << ")";
    throw InternalError(os.str());
}
}  // namespace detail

}  // namespace voxlight
