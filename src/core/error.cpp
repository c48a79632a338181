// SPDX-License-Identifier: MIT
#include "core/error.h"

namespace voxlight {

namespace {
std::string composeMessage(const std::string& source, const std::string& field,
                           const std::string& problem, const std::string& fix) {
    std::string msg = source.empty() ? std::string() : source + ": ";
    if (!field.empty()) msg += field + ": ";
    msg += problem;
    if (!fix.empty()) msg += " (" + fix + ")";
    return msg;
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
