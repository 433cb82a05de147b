// A strict reader of one flat JSON object, the shape of fusiond's JSON log lines: string keys,
// values that are strings or numbers. The tests' own, so that they depend on no JSON library
// (protobuf's Struct crashed inside its map code in the thread-sanitizer build).
#pragma once

#include <cctype>
#include <cstdlib>
#include <map>
#include <optional>
#include <string>

namespace fusion::testing {

namespace json_detail {

inline void SkipSpace(const std::string& s, std::size_t* i) {
  while (*i < s.size() && std::isspace(static_cast<unsigned char>(s[*i]))) ++*i;
}

inline std::optional<std::string> ReadString(const std::string& s, std::size_t* i) {
  if (*i >= s.size() || s[*i] != '"') return std::nullopt;
  std::string out;
  for (++*i; *i < s.size(); ++*i) {
    const char c = s[*i];
    if (c == '"') {
      ++*i;
      return out;
    }
    if (static_cast<unsigned char>(c) < 0x20) return std::nullopt;  // raw control character
    if (c != '\\') {
      out.push_back(c);
      continue;
    }
    if (++*i >= s.size()) return std::nullopt;
    switch (s[*i]) {
      case '"': out.push_back('"'); break;
      case '\\': out.push_back('\\'); break;
      case '/': out.push_back('/'); break;
      case 'n': out.push_back('\n'); break;
      case 'r': out.push_back('\r'); break;
      case 't': out.push_back('\t'); break;
      case 'b': out.push_back('\b'); break;
      case 'f': out.push_back('\f'); break;
      case 'u': {
        if (*i + 4 >= s.size()) return std::nullopt;
        const std::string hex = s.substr(*i + 1, 4);
        char* end = nullptr;
        const long code = std::strtol(hex.c_str(), &end, 16);
        if (end != hex.c_str() + 4 || code >= 0x80) return std::nullopt;  // ASCII escapes only
        out.push_back(static_cast<char>(code));
        *i += 4;
        break;
      }
      default: return std::nullopt;
    }
  }
  return std::nullopt;
}

inline std::optional<std::string> ReadNumber(const std::string& s, std::size_t* i) {
  const char* begin = s.c_str() + *i;
  char* end = nullptr;
  std::strtod(begin, &end);
  if (end == begin) return std::nullopt;
  const std::string text(begin, static_cast<std::size_t>(end - begin));
  *i += text.size();
  return text;
}

}  // namespace json_detail

// The object's members (numbers as their text), or nullopt if `line` is not exactly one flat
// JSON object.
inline std::optional<std::map<std::string, std::string>> ParseFlatJsonObject(
    const std::string& line) {
  using namespace json_detail;
  std::map<std::string, std::string> members;
  std::size_t i = 0;
  SkipSpace(line, &i);
  if (i >= line.size() || line[i++] != '{') return std::nullopt;
  SkipSpace(line, &i);
  if (i < line.size() && line[i] == '}') {
    ++i;
  } else {
    for (;;) {
      SkipSpace(line, &i);
      const auto key = ReadString(line, &i);
      SkipSpace(line, &i);
      if (!key || i >= line.size() || line[i++] != ':') return std::nullopt;
      SkipSpace(line, &i);
      const auto value = i < line.size() && line[i] == '"' ? ReadString(line, &i)
                                                            : ReadNumber(line, &i);
      if (!value || !members.emplace(*key, *value).second) return std::nullopt;
      SkipSpace(line, &i);
      if (i >= line.size()) return std::nullopt;
      if (line[i] == '}') {
        ++i;
        break;
      }
      if (line[i++] != ',') return std::nullopt;
    }
  }
  SkipSpace(line, &i);
  if (i != line.size()) return std::nullopt;
  return members;
}

}  // namespace fusion::testing
