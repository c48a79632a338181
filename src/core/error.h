// SPDX-License-Identifier: MIT
#pragma once
// Error handling for voxlight.
//
// * InputError — bad *user input* (a file, a JSON field, a CLI value). It carries what was being
//   read (`source`, a path or "scene.json"), which part was wrong (`field`) and what to do about it
//   (`fix`). The CLI prints it as one line and exits with code 2; the viewer shows it. Libraries
//   never call exit() or abort() on bad input.
// * VL_CHECK(cond) — an internal invariant, always on (also in Release). Throws InternalError with
//   both operands.
// * VL_DCHECK(cond) — debug-only, for per-sample hot loops.
// * CancelledError — thrown by long algorithms when their cancel flag is raised.
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace voxlight {

/// "a, b, c": the allowed names an InputError's fix lists.
std::string joinNames(const std::vector<std::string>& names);

/// Bad input: "source: field: problem (fix)". what() is one line of valid UTF-8 whatever the parts
/// hold (control characters and bytes that are not UTF-8, e.g. quoted from a damaged file, appear as
/// \xNN); the accessors return the parts as given.
class InputError : public std::runtime_error {
  public:
    InputError(std::string source, std::string field, std::string problem, std::string fix = {});
    const std::string& source() const { return source_; }
    const std::string& field() const { return field_; }
    const std::string& problem() const { return problem_; }
    const std::string& fix() const { return fix_; }

  private:
    std::string source_, field_, problem_, fix_;
};

class InternalError : public std::logic_error {
  public:
    using std::logic_error::logic_error;
};

class CancelledError : public std::runtime_error {
  public:
    CancelledError() : std::runtime_error("cancelled") {}
};

namespace detail {
[[noreturn]] void checkFailed(const char* expr, const char* file, int line,
                              const std::string& values);

template <class A, class B>
std::string formatOperands(const A& a, const B& b) {
    std::ostringstream os;
    os << a << " vs " << b;
    return os.str();
}
}  // namespace detail

}  // namespace voxlight

#define VL_CHECK(cond)                                                               \
    do {                                                                             \
        if (!(cond)) ::voxlight::detail::checkFailed(#cond, __FILE__, __LINE__, {}); \
    } while (0)

#define VL_CHECK_OP(a, op, b)                                                                  \
    do {                                                                                       \
        const auto& vl_a_ = (a);                                                               \
        const auto& vl_b_ = (b);                                                               \
        if (!(vl_a_ op vl_b_))                                                                 \
            ::voxlight::detail::checkFailed(#a " " #op " " #b, __FILE__, __LINE__,             \
                                            ::voxlight::detail::formatOperands(vl_a_, vl_b_)); \
    } while (0)
#define VL_CHECK_EQ(a, b) VL_CHECK_OP(a, ==, b)
#define VL_CHECK_LE(a, b) VL_CHECK_OP(a, <=, b)
#define VL_CHECK_LT(a, b) VL_CHECK_OP(a, <, b)
#define VL_CHECK_GE(a, b) VL_CHECK_OP(a, >=, b)
#define VL_CHECK_GT(a, b) VL_CHECK_OP(a, >, b)

#ifdef NDEBUG
#define VL_DCHECK(cond) \
    do {                \
    } while (0)
#else
#define VL_DCHECK(cond) VL_CHECK(cond)
#endif
