// What fusionctl's commands share: deadlines, failure reports, point arguments, state names.
#include <chrono>
#include <cstdlib>

#include "fusionctl.h"

namespace fusionctl {

void SetDeadline(grpc::ClientContext* context, double seconds) {
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::milliseconds(static_cast<long>(seconds * 1000)));
}

int Failed(const Context& ctx, const grpc::Status& status) {
  if (status.error_code() == grpc::StatusCode::UNAVAILABLE ||
      status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED) {
    return fusion::clients::Fail(
        kTool, "cannot reach fusiond at " + ctx.server + ": " + status.error_message());
  }
  return fusion::clients::Fail(kTool, status.error_message() + " (status " +
                                          std::to_string(static_cast<int>(status.error_code())) +
                                          ")");
}

bool ParsePoint(const std::vector<std::string>& args, std::size_t at, fusion::v1::Point* p) {
  double x, y, z;
  if (at + 3 > args.size() || !fusion::clients::ParseFinite(args[at], &x) ||
      !fusion::clients::ParseFinite(args[at + 1], &y) ||
      !fusion::clients::ParseFinite(args[at + 2], &z)) {
    return false;
  }
  p->set_x(x);
  p->set_y(y);
  p->set_z(z);
  return true;
}

const char* StateName(fusion::v1::VoxelState s) {
  switch (s) {
    case fusion::v1::VOXEL_STATE_OCCUPIED:
      return "occupied";
    case fusion::v1::VOXEL_STATE_FREE:
      return "free";
    default:
      return "unknown";
  }
}

}  // namespace fusionctl
