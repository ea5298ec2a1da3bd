// CHECK for programmer errors: logs the failed condition and where, then
// aborts. Input and runtime errors are statuses, never CHECKs.
#ifndef TRANSTICK_CHECK_H_
#define TRANSTICK_CHECK_H_

#include <cstdio>
#include <cstdlib>

#define TRANSTICK_CHECK(condition)                                                        \
  do {                                                                                    \
    if (!(condition)) {                                                                   \
      std::fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #condition); \
      std::abort();                                                                       \
    }                                                                                     \
  } while (false)

#endif  // TRANSTICK_CHECK_H_
