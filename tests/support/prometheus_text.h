// A strict reader of the Prometheus text exposition format (version 0.0.4), for tests: every
// line must be a HELP, TYPE or sample line; names and labels must be well formed; a family's
// samples follow its TYPE line; histograms must be cumulative and end in +Inf == _count;
// counters must not be negative. Parse returns the samples by series, or the first error with
// its line number.
#pragma once

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace fusion::testing {

struct PrometheusText {
  // "name{a=\"x\",b=\"y\"}" (labels sorted by name, as the key of `samples`) -> value.
  std::map<std::string, double> samples;
  std::map<std::string, std::string> types;  // family -> counter, gauge, histogram, ...
  std::map<std::string, std::string> help;   // family -> text
  std::string error;                         // empty when the whole text is valid

  [[nodiscard]] bool ok() const { return error.empty(); }
  // The value of one series, 0 when absent (a counter not yet incremented).
  [[nodiscard]] double Value(const std::string& series) const {
    const auto it = samples.find(series);
    return it == samples.end() ? 0.0 : it->second;
  }
  [[nodiscard]] bool Has(const std::string& series) const { return samples.count(series) > 0; }

  static PrometheusText Parse(const std::string& text);
};

namespace prometheus_text_detail {

inline bool IsMetricName(const std::string& s) {
  if (s.empty() || std::isdigit(static_cast<unsigned char>(s[0]))) return false;
  for (char c : s) {
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_' && c != ':') return false;
  }
  return true;
}

inline bool IsLabelName(const std::string& s) {
  if (s.empty() || std::isdigit(static_cast<unsigned char>(s[0]))) return false;
  for (char c : s) {
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_') return false;
  }
  return s.rfind("__", 0) != 0;  // reserved for Prometheus itself
}

// A float as Go's ParseFloat reads it (what Prometheus uses), including [+-]Inf and NaN.
inline std::optional<double> ParseValue(const std::string& s) {
  std::string lower;
  for (char c : s) lower += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (lower == "+inf" || lower == "inf") return HUGE_VAL;
  if (lower == "-inf") return -HUGE_VAL;
  if (lower == "nan") return std::nan("");
  if (s.empty() || s.find_first_not_of("0123456789+-.eE") != std::string::npos) return {};
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (end != s.c_str() + s.size()) return {};
  return v;
}

// Labels "{...}" from s[*pos]; on success *pos is past the '}'.
inline bool ParseLabels(const std::string& s, std::size_t* pos,
                        std::map<std::string, std::string>* labels, std::string* error) {
  std::size_t i = *pos + 1;  // past '{'
  while (i < s.size() && s[i] != '}') {
    const std::size_t eq = s.find('=', i);
    if (eq == std::string::npos) return (*error = "label without '='", false);
    const std::string name = s.substr(i, eq - i);
    if (!IsLabelName(name)) return (*error = "bad label name '" + name + "'", false);
    if (eq + 1 >= s.size() || s[eq + 1] != '"') return (*error = "label value not quoted", false);
    std::string value;
    std::size_t j = eq + 2;
    for (; j < s.size() && s[j] != '"'; ++j) {
      if (s[j] == '\\') {
        if (++j >= s.size()) return (*error = "dangling escape", false);
        if (s[j] == 'n') {
          value += '\n';
        } else if (s[j] == '\\' || s[j] == '"') {
          value += s[j];
        } else {
          return (*error = "bad escape in label value", false);
        }
      } else {
        value += s[j];
      }
    }
    if (j >= s.size()) return (*error = "unterminated label value", false);
    if (!labels->emplace(name, value).second) return (*error = "label repeated: " + name, false);
    i = j + 1;
    if (i < s.size() && s[i] == ',')
      ++i;
    else if (i < s.size() && s[i] != '}')
      return (*error = "expected ',' or '}'", false);
  }
  if (i >= s.size()) return (*error = "unterminated label set", false);
  *pos = i + 1;
  return true;
}

inline std::string SeriesKey(const std::string& name,
                             const std::map<std::string, std::string>& labels) {
  std::string key = name;
  if (labels.empty()) return key;
  key += '{';
  bool first = true;
  for (const auto& [k, v] : labels) {
    key += (first ? "" : ",") + k + "=\"" + v + "\"";
    first = false;
  }
  return key + '}';
}

// The family a sample name belongs to, given the family whose TYPE line came last.
inline bool BelongsTo(const std::string& sample, const std::string& family,
                      const std::string& type) {
  if (sample == family) return type != "histogram";
  const auto Suffixed = [&](const char* suffix) { return sample == family + suffix; };
  if (type == "histogram") return Suffixed("_bucket") || Suffixed("_sum") || Suffixed("_count");
  if (type == "summary") return Suffixed("_sum") || Suffixed("_count");
  return false;
}

}  // namespace prometheus_text_detail

// Long because one pass checks the format's rules in the order a line meets them; the
// pieces that stand alone are in prometheus_text_detail.
inline PrometheusText PrometheusText::Parse(const std::string& text) {
  namespace d = prometheus_text_detail;
  PrometheusText out;
  std::string family, type;                   // the family being read
  std::set<std::string> finished;             // families whose samples are over
  std::map<std::string, double> last_bucket;  // histogram series (no le) -> previous bucket
  std::istringstream in(text);
  std::string line;
  int number = 0;
  const auto Fail = [&](const std::string& message) {
    out.error = "line " + std::to_string(number) + ": " + message + ": '" + line + "'";
    return out;
  };
  if (!text.empty() && text.back() != '\n') return (number = 0, Fail("no final newline"));
  while (std::getline(in, line)) {
    ++number;
    if (line.empty()) return Fail("empty line");
    if (line[0] == '#') {
      std::istringstream words(line);
      std::string hash, keyword, name, rest;
      words >> hash >> keyword >> name;
      std::getline(words, rest);
      if (hash != "#" || (keyword != "HELP" && keyword != "TYPE")) return Fail("not HELP or TYPE");
      if (!d::IsMetricName(name)) return Fail("bad metric name");
      if (!rest.empty() && rest[0] == ' ') rest.erase(0, 1);
      if (name != family) {
        if (!family.empty()) finished.insert(family);
        if (finished.count(name)) return Fail("family seen before: " + name);
        family = name;
        type = "untyped";
      }
      if (keyword == "HELP") {
        if (!out.help.emplace(name, rest).second) return Fail("HELP repeated");
      } else {
        static const std::set<std::string> kTypes{"counter", "gauge", "histogram", "summary",
                                                  "untyped"};
        if (!kTypes.count(rest)) return Fail("unknown type");
        if (!out.types.emplace(name, rest).second) return Fail("TYPE repeated");
        type = rest;
      }
      continue;
    }
    std::size_t pos = 0;
    while (pos < line.size() && line[pos] != '{' && line[pos] != ' ') ++pos;
    const std::string name = line.substr(0, pos);
    if (!d::IsMetricName(name)) return Fail("bad metric name");
    std::map<std::string, std::string> labels;
    if (pos < line.size() && line[pos] == '{' && !d::ParseLabels(line, &pos, &labels, &out.error)) {
      return Fail(out.error);
    }
    if (pos >= line.size() || line[pos] != ' ') return Fail("no value");
    std::istringstream fields(line.substr(pos + 1));
    std::string value_text, timestamp, extra;
    fields >> value_text >> timestamp >> extra;
    const auto value = d::ParseValue(value_text);
    if (!value) return Fail("bad value");
    if (!timestamp.empty() && timestamp.find_first_not_of("-0123456789") != std::string::npos) {
      return Fail("bad timestamp");
    }
    if (!extra.empty()) return Fail("trailing text");
    if (family.empty() || !d::BelongsTo(name, family, type)) {
      return Fail("sample outside its family's TYPE block");
    }
    if (type == "counter" && !(*value >= 0)) return Fail("negative counter");
    if (type == "histogram" && name == family + "_bucket") {
      const auto le = labels.find("le");
      if (le == labels.end() || !d::ParseValue(le->second)) return Fail("bucket without le");
      const bool inf = std::isinf(*d::ParseValue(le->second));
      auto others = labels;
      others.erase("le");
      const std::string series = d::SeriesKey(family, others);
      if (last_bucket.count(series) && *value < last_bucket[series]) {
        return Fail("buckets not cumulative");
      }
      last_bucket[series] = *value;
      if (inf) {
        const auto count = out.samples.find(d::SeriesKey(family + "_count", others));
        if (count != out.samples.end() && count->second != *value) return Fail("+Inf != _count");
      }
    }
    if (!out.samples.emplace(d::SeriesKey(name, labels), *value).second) {
      return Fail("series repeated");
    }
  }
  return out;
}

}  // namespace fusion::testing
