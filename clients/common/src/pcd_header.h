// The first steps of ReadPcd (pcd_import.cc): the PCD header up to its DATA line, and where the
// x, y and z values sit in a point. Private to clients/common/src.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "fusion/core/status.h"

namespace fusion::clients {

struct PcdField {
  std::string name;
  std::size_t size_bytes = 4;
  char type = 'F';
  std::size_t count = 1;
  std::size_t offset_bytes = 0;  // within a point (binary)
  std::size_t first_value = 0;   // index of its first value among a point's values (ascii)
};

struct PcdHeader {
  std::vector<PcdField> fields;
  std::uint64_t width = 0, height = 1, points = 0;  // points = width x height, checked
  double viewpoint[7] = {0, 0, 0, 1, 0, 0, 0};      // tx ty tz qw qx qy qz, not yet checked
  std::string data_kind;                            // the DATA value, not yet checked
  std::size_t data_offset_bytes = 0;                // first byte after the DATA line
  std::size_t line_count = 0;  // lines up to DATA (ascii data's line numbers go on)
};

struct PcdLayout {
  std::size_t point_step_bytes = 0;      // one point (binary)
  std::size_t values_per_point = 0;      // one line (ascii)
  std::size_t xyz_field[3] = {0, 0, 0};  // indices of the fields x, y and z (TYPE F, SIZE 4 or 8)
};

// Parses the header of a whole PCD file's content. Messages name the line but not the file.
Status ParsePcdHeader(const std::string& content, PcdHeader* header);
// Fills the fields' offsets and finds x, y and z; bounds a point to 1 MiB.
Status LayOutPcdFields(PcdHeader* header, PcdLayout* layout);

}  // namespace fusion::clients
