// PCD header parsing (v0.5-0.7 keywords) and the field layout it implies.
#include "pcd_header.h"

#include <algorithm>
#include <sstream>

#include "fusion/clients/cli.h"

namespace fusion::clients {
namespace {

// SIZE, TYPE or COUNT: one value per field of the FIELDS line before it.
Status ParseFieldAttribute(const std::string& key, const std::vector<std::string>& values,
                           const std::string& where, std::vector<PcdField>* fields) {
  if (values.size() != fields->size())
    return Status::Error(where + ": " + std::to_string(values.size()) + " values for " +
                         std::to_string(fields->size()) + " fields");
  for (std::size_t i = 0; i < values.size(); ++i) {
    std::uint64_t n = 0;
    if (key == "TYPE") {
      if (values[i].size() != 1 || std::string("FIU").find(values[i][0]) == std::string::npos)
        return Status::Error(where + ": unknown type '" + values[i] + "'");
      (*fields)[i].type = values[i][0];
    } else if (Status s = ParseUint(where, values[i], &n); !s.ok() || n == 0 || n > 1u << 20) {
      return Status::Error(where + ": bad value '" + values[i] + "'");
    } else {
      (key == "SIZE" ? (*fields)[i].size_bytes : (*fields)[i].count) = n;
    }
  }
  return Status::Ok();
}

// One "KEY value..." line; *points_given records a POINTS line.
Status ParseHeaderLine(const std::string& key, const std::vector<std::string>& values,
                       const std::string& where, PcdHeader* header, bool* points_given) {
  if (key == "VERSION") return Status::Ok();
  if (key == "FIELDS" || key == "COLUMNS") {
    header->fields.assign(values.size(), PcdField{});
    for (std::size_t i = 0; i < values.size(); ++i) header->fields[i].name = values[i];
  } else if (key == "SIZE" || key == "TYPE" || key == "COUNT") {
    return ParseFieldAttribute(key, values, where, &header->fields);
  } else if (key == "WIDTH" || key == "HEIGHT" || key == "POINTS") {
    std::uint64_t n = 0;
    if (values.size() != 1) return Status::Error(where + ": expected one value");
    if (Status s = ParseUint(where, values[0], &n); !s.ok()) return s;
    if (key == "WIDTH") header->width = n;
    if (key == "HEIGHT") header->height = n;
    if (key == "POINTS") header->points = n, *points_given = true;
  } else if (key == "VIEWPOINT") {
    if (values.size() != 7) return Status::Error(where + ": expected tx ty tz qw qx qy qz");
    for (int i = 0; i < 7; ++i) {
      if (Status s = ParseDouble(where, values[i], &header->viewpoint[i]); !s.ok()) return s;
    }
  } else if (key == "DATA") {
    if (values.size() != 1)
      return Status::Error(where + ": expected ascii, binary or binary_compressed");
    header->data_kind = values[0];
  } else {
    return Status::Error(where + ": unknown header keyword");
  }
  return Status::Ok();
}

}  // namespace

Status ParsePcdHeader(const std::string& content, PcdHeader* header) {
  bool points_given = false;
  std::size_t pos = 0;
  while (header->data_kind.empty()) {
    if (pos >= content.size()) return Status::Error("header ends before the DATA line");
    std::size_t eol = content.find('\n', pos);
    if (eol == std::string::npos) eol = content.size();
    std::string line = content.substr(pos, eol - pos);
    pos = std::min(eol + 1, content.size());  // a last line without '\n' ends the file
    ++header->line_count;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    std::istringstream words(line);
    std::string key;
    words >> key;
    std::vector<std::string> values;
    for (std::string w; words >> w;) values.push_back(w);
    const std::string where =
        "header line " + std::to_string(header->line_count) + " (" + key + ")";
    if (Status s = ParseHeaderLine(key, values, where, header, &points_given); !s.ok()) return s;
  }
  header->data_offset_bytes = pos;
  if (header->fields.empty()) return Status::Error("no FIELDS line");
  if (!points_given) header->points = header->width * header->height;
  if (header->width * header->height != header->points || header->points == 0) {
    return Status::Error("WIDTH x HEIGHT = " + std::to_string(header->width * header->height) +
                         " but POINTS = " + std::to_string(header->points));
  }
  if (header->points > (1ull << 28))
    return Status::Error("implausible point count " + std::to_string(header->points));
  return Status::Ok();
}

Status LayOutPcdFields(PcdHeader* header, PcdLayout* layout) {
  std::vector<PcdField>& fields = header->fields;
  std::size_t point_step = 0, values_per_point = 0;
  int xyz_field[3] = {-1, -1, -1};
  // A point of at most 1 MiB (and so points x point size below 2^48: no overflow in the
  // decoders).
  constexpr std::size_t kMaxPointBytes = std::size_t{1} << 20;
  for (std::size_t i = 0; i < fields.size(); ++i) {
    fields[i].offset_bytes = point_step;
    fields[i].first_value = values_per_point;
    if (fields[i].count > kMaxPointBytes / fields[i].size_bytes ||
        point_step + fields[i].size_bytes * fields[i].count > kMaxPointBytes) {
      return Status::Error("a point of more than 1 MiB (SIZE x COUNT summed over the fields)");
    }
    point_step += fields[i].size_bytes * fields[i].count;
    values_per_point += fields[i].count;
    for (int a = 0; a < 3; ++a) {
      if (fields[i].name == std::string(1, static_cast<char>('x' + a)))
        xyz_field[a] = static_cast<int>(i);
    }
  }
  for (int a = 0; a < 3; ++a) {
    if (xyz_field[a] < 0)
      return Status::Error(std::string("no field '") + static_cast<char>('x' + a) + "'");
    const PcdField& f = fields[static_cast<std::size_t>(xyz_field[a])];
    if (f.type != 'F' || (f.size_bytes != 4 && f.size_bytes != 8)) {
      return Status::Error("field " + f.name + " must be TYPE F with SIZE 4 or 8");
    }
    layout->xyz_field[a] = static_cast<std::size_t>(xyz_field[a]);
  }
  layout->point_step_bytes = point_step;
  layout->values_per_point = values_per_point;
  return Status::Ok();
}

}  // namespace fusion::clients
