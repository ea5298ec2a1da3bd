// What the benchmark programs share: parsing their flags' numbers, timing,
// and medians.
#ifndef TRANSTICK_BENCH_BENCH_UTIL_H_
#define TRANSTICK_BENCH_BENCH_UTIL_H_

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <string>
#include <vector>

namespace transtick::bench {

// An integer in [lo, hi], the whole string; false otherwise.
inline bool ParseInt(const std::string& s, int lo, int hi, int* out) {
  char* end = nullptr;
  long v = std::strtol(s.c_str(), &end, 10);
  if (s.empty() || *end != '\0' || v < lo || v > hi) return false;
  *out = static_cast<int>(v);
  return true;
}

// "WxH", each in [1, max].
inline bool ParseSize(const std::string& s, int max, int* width, int* height) {
  size_t x = s.find('x');
  return x != std::string::npos && ParseInt(s.substr(0, x), 1, max, width) &&
         ParseInt(s.substr(x + 1), 1, max, height);
}

inline double MsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

inline double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace transtick::bench

#endif  // TRANSTICK_BENCH_BENCH_UTIL_H_
