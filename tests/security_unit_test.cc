// The pieces of common/security.h that need no network: the token file,
// escaping client strings, loopback addresses.
#include <random>
#include <string>

#include "gtest/gtest.h"
#include "security.h"

namespace transtick {
namespace {

TEST(TokenTableTest, ParsesClientsAndRefusesWhatIsWrong) {
  auto t = TokenTable::Parse(
      "# clients\nalice  aaaaaaaaaaaaaaaa1\n\nops bbbbbbbbbbbbbbbb2 admin  # the team\n", "t");
  ASSERT_TRUE(t.ok()) << t.status();
  EXPECT_EQ(t->size(), 2u);
  ASSERT_TRUE(t->Find("aaaaaaaaaaaaaaaa1").has_value());
  EXPECT_EQ(t->Find("aaaaaaaaaaaaaaaa1")->name, "alice");
  EXPECT_FALSE(t->Find("aaaaaaaaaaaaaaaa1")->admin);
  EXPECT_TRUE(t->Find("bbbbbbbbbbbbbbbb2")->admin);
  EXPECT_FALSE(t->Find("aaaaaaaaaaaaaaaa").has_value());   // a prefix
  EXPECT_FALSE(t->Find("aaaaaaaaaaaaaaaa12").has_value());  // longer
  EXPECT_FALSE(t->Find("").has_value());
  for (const char* bad : {"alice short\n", "alice aaaaaaaaaaaaaaaa1 root\n",
                          "al/ice aaaaaaaaaaaaaaaa1\n", "a aaaaaaaaaaaaaaaa1\na aaaaaaaaaaaaaaaa2\n",
                          "a aaaaaaaaaaaaaaaa1\nb aaaaaaaaaaaaaaaa1\n", "# nobody\n", "lonely\n"}) {
    auto r = TokenTable::Parse(bad, "tokens");
    EXPECT_FALSE(r.ok()) << bad;
    EXPECT_NE(r.status().message().find("tokens"), std::string::npos) << r.status();
  }
}

TEST(PrintableTest, NoClientStringKeepsAControlCharacter) {
  EXPECT_EQ(Printable("plain name-1.nrrd"), "plain name-1.nrrd");
  EXPECT_EQ(Printable("a\nb\r\tc\\"), "a\\nb\\r\\tc\\\\");
  EXPECT_EQ(Printable("\x1b[2K"), "\\x1b[2K");
  EXPECT_EQ(Printable("Gr\xc3\xa4tz"), "Gr\xc3\xa4tz");      // UTF-8 stays
  EXPECT_EQ(Printable("\xc2\x9b" "31m"), "\\xc2\\x9b31m");  // C1 CSI does not
  std::mt19937 rng(7);
  for (int i = 0; i < 10000; ++i) {
    std::string s(rng() % 40, '\0');
    for (char& c : s) c = static_cast<char>(rng());
    const std::string p = Printable(s);
    for (size_t k = 0; k < p.size(); ++k) {
      const auto c = static_cast<unsigned char>(p[k]);
      ASSERT_FALSE(c < 0x20 || c == 0x7f) << i;
      ASSERT_FALSE(c == 0xc2 && k + 1 < p.size() &&
                   (static_cast<unsigned char>(p[k + 1]) & 0xe0) == 0x80)
          << i;
    }
  }
}

TEST(LoopbackTest, KnowsLoopbackAddresses) {
  for (const char* a : {"127.0.0.1:7000", "127.1.2.3:0", "localhost:1", "[::1]:7001"}) {
    EXPECT_TRUE(IsLoopback(a)) << a;
  }
  for (const char* a : {"0.0.0.0:7000", "[::]:7000", "10.0.0.1:1", "example:7000", "128.0.0.1:1"}) {
    EXPECT_FALSE(IsLoopback(a)) << a;
  }
}

}  // namespace
}  // namespace transtick
