// fusionctl --json: every result as one line of JSON, the proto3 JSON mapping of the reply
// message, so the schema is the .proto itself (docs/clients.md).
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>

#include <cstdio>

#include "fusionctl.h"

namespace fusionctl {

void PrintJson(const google::protobuf::Message& message) {
  google::protobuf::util::JsonPrintOptions options;
  // Scripts read fields by their .proto names and need zero counters present.
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields = true;
  std::string json;
  const auto status = google::protobuf::util::MessageToJsonString(message, &json, options);
  if (!status.ok()) {
    // Only a message the mapping cannot express (none of fusion.v1's): say so, keep the line.
    json = "{}";
    std::fprintf(stderr, "%s: no JSON for %s: %s\n", kTool, message.GetTypeName().c_str(),
                 std::string(status.message()).c_str());
  }
  std::printf("%s\n", json.c_str());
  std::fflush(stdout);  // watch's documents arrive as they happen
}

void PrintJsonFields(const std::map<std::string, std::string>& strings,
                     const std::map<std::string, double>& numbers) {
  google::protobuf::Struct document;
  auto& fields = *document.mutable_fields();
  for (const auto& [name, value] : strings) fields[name].set_string_value(value);
  for (const auto& [name, value] : numbers) fields[name].set_number_value(value);
  PrintJson(document);
}

}  // namespace fusionctl
