// Checks for programmer errors, after pbrt-v4's util/check.h: a failed
// check logs the condition, where it failed and (for the comparisons) both
// values, then aborts. Input and runtime errors are statuses, never CHECKs.
//
//   TRANSTICK_CHECK(cond)              always on
//   TRANSTICK_CHECK_EQ(a, b)           also _NE, _LT, _LE, _GT, _GE: a op b,
//                                      printing a and b when it fails
//   TRANSTICK_DCHECK(cond)             a hot path's REQUIRES: on in debug
//   TRANSTICK_DCHECK_EQ(a, b) ...      builds, nothing at all with NDEBUG
//
// Each operand is evaluated once. A DCHECK's operands are not evaluated
// when NDEBUG is defined (they are still compiled, so they cannot rot), so
// they must not have side effects. Values print with operator<< when they
// have one; enums print as their underlying integer, anything else as "?".
#ifndef TRANSTICK_CHECK_H_
#define TRANSTICK_CHECK_H_

#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <type_traits>

namespace transtick::check_internal {

template <typename T>
std::string Print(const T& value) {
  std::ostringstream out;
  if constexpr (requires { out << value; }) {
    if constexpr (std::is_same_v<T, char> || std::is_same_v<T, signed char> ||
                  std::is_same_v<T, unsigned char>) {
      out << static_cast<int>(value);  // uint8_t ids, not characters
    } else {
      out << value;
    }
  } else if constexpr (std::is_enum_v<T>) {
    out << static_cast<long long>(static_cast<std::underlying_type_t<T>>(value));
  } else {
    out << "?";
  }
  return out.str();
}

// Out of line and cold, so that a check costs its comparison and a branch.
[[noreturn, gnu::cold, gnu::noinline]] inline void Fail(const char* file, int line,
                                                        const char* what) {
  std::fprintf(stderr, "%s:%d: CHECK failed: %s\n", file, line, what);
  std::fflush(stderr);
  std::abort();
}

template <typename A, typename B>
[[noreturn, gnu::cold, gnu::noinline]] void FailOp(const char* file, int line, const char* a_text,
                                                   const char* op, const char* b_text, const A& a,
                                                   const B& b) {
  std::fprintf(stderr, "%s:%d: CHECK failed: %s %s %s with %s = %s, %s = %s\n", file, line, a_text,
               op, b_text, a_text, Print(a).c_str(), b_text, Print(b).c_str());
  std::fflush(stderr);
  std::abort();
}

}  // namespace transtick::check_internal

#define TRANSTICK_CHECK(condition)                                       \
  do {                                                                   \
    if (!(condition)) [[unlikely]]                                       \
      ::transtick::check_internal::Fail(__FILE__, __LINE__, #condition); \
  } while (false)

#define TRANSTICK_CHECK_OP_(a, b, op)                                                         \
  do {                                                                                        \
    const auto& transtick_check_a = (a);                                                      \
    const auto& transtick_check_b = (b);                                                      \
    if (!(transtick_check_a op transtick_check_b)) [[unlikely]]                               \
      ::transtick::check_internal::FailOp(__FILE__, __LINE__, #a, #op, #b, transtick_check_a, \
                                          transtick_check_b);                                 \
  } while (false)

#define TRANSTICK_CHECK_EQ(a, b) TRANSTICK_CHECK_OP_(a, b, ==)
#define TRANSTICK_CHECK_NE(a, b) TRANSTICK_CHECK_OP_(a, b, !=)
#define TRANSTICK_CHECK_LT(a, b) TRANSTICK_CHECK_OP_(a, b, <)
#define TRANSTICK_CHECK_LE(a, b) TRANSTICK_CHECK_OP_(a, b, <=)
#define TRANSTICK_CHECK_GT(a, b) TRANSTICK_CHECK_OP_(a, b, >)
#define TRANSTICK_CHECK_GE(a, b) TRANSTICK_CHECK_OP_(a, b, >=)

#ifdef NDEBUG
// Nothing is evaluated: sizeof only compiles its operand.
#define TRANSTICK_DCHECK(condition) \
  do {                              \
    (void)sizeof(!(condition));     \
  } while (false)
#define TRANSTICK_DCHECK_OP_(a, b, op) \
  do {                                 \
    (void)sizeof((a)op(b));            \
  } while (false)
#else
#define TRANSTICK_DCHECK(condition) TRANSTICK_CHECK(condition)
#define TRANSTICK_DCHECK_OP_(a, b, op) TRANSTICK_CHECK_OP_(a, b, op)
#endif

#define TRANSTICK_DCHECK_EQ(a, b) TRANSTICK_DCHECK_OP_(a, b, ==)
#define TRANSTICK_DCHECK_NE(a, b) TRANSTICK_DCHECK_OP_(a, b, !=)
#define TRANSTICK_DCHECK_LT(a, b) TRANSTICK_DCHECK_OP_(a, b, <)
#define TRANSTICK_DCHECK_LE(a, b) TRANSTICK_DCHECK_OP_(a, b, <=)
#define TRANSTICK_DCHECK_GT(a, b) TRANSTICK_DCHECK_OP_(a, b, >)
#define TRANSTICK_DCHECK_GE(a, b) TRANSTICK_DCHECK_OP_(a, b, >=)

#endif  // TRANSTICK_CHECK_H_
