// The checks of transtick/check.h: a failed CHECK names the condition and
// aborts, a failed CHECK_op prints both values, and a DCHECK is a CHECK in
// debug builds and evaluates nothing with NDEBUG.
#include "transtick/check.h"

#include <cstdint>
#include <string>

#include "gtest/gtest.h"

namespace transtick {
namespace {

enum class Colour : uint8_t { kRed = 3, kBlue = 7 };

struct Opaque {
  int v;
  bool operator==(const Opaque& o) const { return v == o.v; }
};

// Death tests fork; "threadsafe" re-executes the binary, which stays safe
// should another test have started threads.
class CheckDeathTest : public ::testing::Test {
 protected:
  void SetUp() override { GTEST_FLAG_SET(death_test_style, "threadsafe"); }
};

TEST_F(CheckDeathTest, CheckNamesTheCondition) {
  int x = 2;
  TRANSTICK_CHECK(x == 2);
  EXPECT_DEATH(TRANSTICK_CHECK(x == 3), "CHECK failed: x == 3");
}

TEST_F(CheckDeathTest, CheckEqPrintsBothValues) {
  const int width = 400;
  const int64_t pixel = 160001;
  TRANSTICK_CHECK_EQ(width, 400);
  EXPECT_DEATH(TRANSTICK_CHECK_EQ(pixel, width * 2),
               "CHECK failed: pixel == width \\* 2 with pixel = 160001, width \\* 2 = 800");
}

TEST_F(CheckDeathTest, EveryComparisonFailsWithItsValues) {
  const int a = 1, b = 2;
  TRANSTICK_CHECK_NE(a, b);
  TRANSTICK_CHECK_LT(a, b);
  TRANSTICK_CHECK_LE(a, b);
  TRANSTICK_CHECK_LE(a, a);
  TRANSTICK_CHECK_GT(b, a);
  TRANSTICK_CHECK_GE(b, a);
  TRANSTICK_CHECK_GE(b, b);
  EXPECT_DEATH(TRANSTICK_CHECK_NE(a, a), "a != a with a = 1, a = 1");
  EXPECT_DEATH(TRANSTICK_CHECK_LT(b, a), "b < a with b = 2, a = 1");
  EXPECT_DEATH(TRANSTICK_CHECK_LE(b, a), "b <= a with b = 2, a = 1");
  EXPECT_DEATH(TRANSTICK_CHECK_GT(a, b), "a > b with a = 1, b = 2");
  EXPECT_DEATH(TRANSTICK_CHECK_GE(a, b), "a >= b with a = 1, b = 2");
}

TEST_F(CheckDeathTest, ValuesWithoutAStreamOperatorStillPrint) {
  const uint8_t material = 200;
  EXPECT_DEATH(TRANSTICK_CHECK_EQ(material, 3), "material = 200, 3 = 3");
  EXPECT_DEATH(TRANSTICK_CHECK_EQ(Colour::kRed, Colour::kBlue),
               "Colour::kRed = 3, Colour::kBlue = 7");
  EXPECT_DEATH(TRANSTICK_CHECK_EQ(Opaque{1}, Opaque{2}), "= \\?, Opaque\\{2\\} = \\?");
}

TEST(CheckTest, OperandsAreEvaluatedOnce) {
  int calls = 0;
  auto next = [&] { return ++calls; };
  TRANSTICK_CHECK_EQ(next(), 1);
  TRANSTICK_CHECK(next() == 2);
  EXPECT_EQ(calls, 2);
}

#ifdef NDEBUG
TEST(CheckTest, DcheckEvaluatesNothingInReleaseBuilds) {
  int calls = 0;
  auto fail = [&] {
    ++calls;
    return false;
  };
  TRANSTICK_DCHECK(fail());
  TRANSTICK_DCHECK_EQ(fail(), true);
  TRANSTICK_DCHECK_NE(calls, calls);
  TRANSTICK_DCHECK_LT(1, 0);
  TRANSTICK_DCHECK_LE(1, 0);
  TRANSTICK_DCHECK_GT(0, 1);
  TRANSTICK_DCHECK_GE(0, 1);
  EXPECT_EQ(calls, 0);
}
#else
TEST_F(CheckDeathTest, DcheckIsACheckInDebugBuilds) {
  const int z = 45, depth = 45;
  TRANSTICK_DCHECK_LT(z - 1, depth);
  EXPECT_DEATH(TRANSTICK_DCHECK(z < depth), "CHECK failed: z < depth");
  EXPECT_DEATH(TRANSTICK_DCHECK_LT(z, depth), "z < depth with z = 45, depth = 45");
}
#endif

}  // namespace
}  // namespace transtick
