#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "io/text.h"

namespace lodstream::io::text {
namespace {

bool parse(const std::string& s, double* v, size_t* used = nullptr) {
  const char* p = s.data();
  const bool ok = parse_double(p, s.data() + s.size(), v);
  if (used) *used = static_cast<size_t>(p - s.data());
  return ok;
}

TEST(Text, ParseDoubleForms) {
  double v = 0;
  EXPECT_TRUE(parse("1.5", &v));
  EXPECT_EQ(v, 1.5);
  EXPECT_TRUE(parse("  -2.5e-3 ", &v));
  EXPECT_EQ(v, -2.5e-3);
  EXPECT_TRUE(parse("+4E2", &v));
  EXPECT_EQ(v, 400.0);
  EXPECT_TRUE(parse("\t.5\r", &v));
  EXPECT_EQ(v, 0.5);
  EXPECT_TRUE(parse("7\n", &v));
  EXPECT_EQ(v, 7.0);
  // Correctly rounded, as from strtod.
  EXPECT_TRUE(parse("0.1", &v));
  EXPECT_EQ(v, 0.1);
  EXPECT_TRUE(parse("nan", &v));
  EXPECT_TRUE(std::isnan(v));
}

TEST(Text, ParseDoubleRejects) {
  double v = 0;
  EXPECT_FALSE(parse("", &v));
  EXPECT_FALSE(parse("x", &v));
  EXPECT_FALSE(parse("1.5x", &v));
  EXPECT_FALSE(parse("--1", &v));
  // Never reads past the end: "1" followed by bytes outside the range.
  const std::string s = "12345";
  const char* p = s.data();
  EXPECT_TRUE(parse_double(p, s.data() + 2, &v));
  EXPECT_EQ(v, 12.0);
}

TEST(Text, OutOfRangeNumbersRoundLikeStrtod) {
  double v = 1;
  EXPECT_TRUE(parse("1e-400", &v));
  EXPECT_EQ(v, 0.0);
  EXPECT_TRUE(parse("-4e-320", &v));  // a denormal
  EXPECT_EQ(v, -4e-320);
  EXPECT_TRUE(parse("1e999", &v));  // overflow is infinity: readers report it as not finite
  EXPECT_TRUE(std::isinf(v));
  const std::string long_tiny = "0." + std::string(600, '0') + "1";
  EXPECT_TRUE(parse(long_tiny, &v));
  EXPECT_EQ(v, 0.0);
}

TEST(Text, Int64AndNewlines) {
  const std::string s = "  -17/3";
  const char* p = s.data();
  int64_t i = 0;
  ASSERT_TRUE(parse_int64(p, s.data() + s.size(), &i));
  EXPECT_EQ(i, -17);
  EXPECT_EQ(*p, '/');
  const std::string t = "a\nb\r\n\nc";
  EXPECT_EQ(count_newlines(t.data(), t.data() + t.size()), 3u);
  const double ok[3] = {1, 2, 3}, bad[3] = {1, INFINITY, 3};
  EXPECT_TRUE(finite3(ok));
  EXPECT_FALSE(finite3(bad));
}

}  // namespace
}  // namespace lodstream::io::text
