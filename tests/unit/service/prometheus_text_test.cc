// The strict Prometheus text-format reader the metrics integration test relies on
// (tests/support/prometheus_text.h): it must accept what the format allows and refuse each
// kind of malformed line, or that test would prove nothing.
#include "../../support/prometheus_text.h"

#include <gtest/gtest.h>

#include <string>

namespace fusion::testing {
namespace {

const std::string kValid =
    "# HELP a_total Things.\n"
    "# TYPE a_total counter\n"
    "a_total{sensor=\"s\\\"1\\\\\",reason=\"x\"} 3\n"
    "a_total{sensor=\"t\",reason=\"x\",} 0 1700000000000\n"
    "# HELP g A gauge.\n"
    "# TYPE g gauge\n"
    "g -1.5e-3\n"
    "# HELP h_seconds Durations.\n"
    "# TYPE h_seconds histogram\n"
    "h_seconds_count 2\n"
    "h_seconds_sum 0.75\n"
    "h_seconds_bucket{le=\"0.5\"} 1\n"
    "h_seconds_bucket{le=\"+Inf\"} 2\n"
    "# HELP s A summary.\n"
    "# TYPE s summary\n"
    "s{quantile=\"0.5\"} Nan\n"
    "s_sum 0\n"
    "s_count 0\n";

TEST(PrometheusTextTest, ReadsEveryKindOfLine) {
  const auto parsed = PrometheusText::Parse(kValid);
  ASSERT_TRUE(parsed.ok()) << parsed.error;
  EXPECT_EQ(parsed.Value(R"(a_total{reason="x",sensor="s"1\"})"), 3.0);  // labels sorted
  EXPECT_EQ(parsed.Value(R"(a_total{reason="x",sensor="t"})"), 0.0);
  EXPECT_TRUE(parsed.Has(R"(a_total{reason="x",sensor="t"})"));
  EXPECT_DOUBLE_EQ(parsed.Value("g"), -1.5e-3);
  EXPECT_EQ(parsed.Value(R"(h_seconds_bucket{le="+Inf"})"), 2.0);
  EXPECT_EQ(parsed.types.at("h_seconds"), "histogram");
  EXPECT_EQ(parsed.help.at("g"), "A gauge.");
  EXPECT_FALSE(parsed.Has("absent"));
}

TEST(PrometheusTextTest, RefusesEachMalformedLine) {
  const std::pair<std::string, std::string> cases[] = {
      {"no final newline", "# TYPE g gauge\ng 1"},
      {"empty line", "# TYPE g gauge\n\ng 1\n"},
      {"other comment", "# a comment\n"},
      {"bad type", "# TYPE g meter\n"},
      {"bad metric name", "# TYPE g gauge\n1g 1\n"},
      {"bad label name", "# TYPE g gauge\ng{1a=\"x\"} 1\n"},
      {"reserved label", "# TYPE g gauge\ng{__name__=\"x\"} 1\n"},
      {"unquoted label", "# TYPE g gauge\ng{a=x} 1\n"},
      {"unterminated label", "# TYPE g gauge\ng{a=\"x} 1\n"},
      {"bad escape", "# TYPE g gauge\ng{a=\"\\t\"} 1\n"},
      {"repeated label", "# TYPE g gauge\ng{a=\"x\",a=\"y\"} 1\n"},
      {"no value", "# TYPE g gauge\ng\n"},
      {"bad value", "# TYPE g gauge\ng one\n"},
      {"trailing text", "# TYPE g gauge\ng 1 2 3\n"},
      {"untyped sample", "g 1\n"},
      {"foreign sample", "# TYPE g gauge\nh 1\n"},
      {"negative counter", "# TYPE c_total counter\nc_total -1\n"},
      {"repeated series", "# TYPE g gauge\ng 1\ng 2\n"},
      {"repeated TYPE", "# TYPE g gauge\n# TYPE g gauge\n"},
      {"family split", "# TYPE g gauge\ng 1\n# TYPE h gauge\nh 1\n# HELP g again\n"},
      {"bucket without le", "# TYPE h histogram\nh_bucket 1\n"},
      {"not cumulative", "# TYPE h histogram\nh_bucket{le=\"1\"} 2\nh_bucket{le=\"2\"} 1\n"},
      {"+Inf != count", "# TYPE h histogram\nh_count 2\nh_bucket{le=\"+Inf\"} 1\n"},
      {"histogram without suffix", "# TYPE h histogram\nh 1\n"},
  };
  for (const auto& [what, text] : cases) {
    const auto parsed = PrometheusText::Parse(text);
    EXPECT_FALSE(parsed.ok()) << what;
  }
}

}  // namespace
}  // namespace fusion::testing
