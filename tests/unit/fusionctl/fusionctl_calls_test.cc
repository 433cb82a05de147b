// fusionctl against a fake fusiond: --json on every command, every Stats field, the box
// summary, status names and the server's detail, deadlines reported as deadlines, render's
// extension, planes' precision and the bearer token on every call.
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>
#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "grpc/health/v1/health.pb.h"
#include "run_fusionctl.h"

namespace fusionctl {
namespace {

using testing::FakeFusiondTest;
using testing::Lines;
namespace v1 = fusion::v1;
namespace pb = google::protobuf;

// A Stats with every field set, each scalar to a value of its own.
v1::Stats FullStats() {
  v1::Stats s;
  const auto* d = s.GetDescriptor();
  const auto* r = s.GetReflection();
  for (int i = 0; i < d->field_count(); ++i) {
    const auto* f = d->field(i);
    if (f->is_map()) continue;
    switch (f->cpp_type()) {
      case pb::FieldDescriptor::CPPTYPE_UINT64:
        r->SetUInt64(&s, f, 1000 + f->number());
        break;
      case pb::FieldDescriptor::CPPTYPE_DOUBLE:
        r->SetDouble(&s, f, 0.5 + f->number());
        break;
      case pb::FieldDescriptor::CPPTYPE_STRING:
        r->SetString(&s, f, "text-" + f->name());
        break;
      default:
        ADD_FAILURE() << "Stats field of a new type: " << f->name();
    }
  }
  (*s.mutable_rejected_by_reason())["bad_pose"] = 4;
  return s;
}

class FusionctlCallsTest : public FakeFusiondTest {
 protected:
  std::string TempPath(const std::string& name) {
    return ::testing::TempDir() + "fusionctl_" + std::to_string(getpid()) + "_" + name;
  }
};

TEST_F(FusionctlCallsTest, StatsShowsEveryField) {
  service_.stats = FullStats();
  const auto r = Fusionctl({"stats"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto* d = v1::Stats::descriptor();
  for (int i = 0; i < d->field_count(); ++i) {
    EXPECT_NE(r.out.find(d->field(i)->name()), std::string::npos)
        << "stats does not show " << d->field(i)->name() << ":\n"
        << r.out;
  }
  EXPECT_NE(r.out.find("clouds_in_map        1015\n"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("bad_pose"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("text-last_snapshot_error"), std::string::npos) << r.out;

  const auto j = Fusionctl({"--json", "stats"});
  ASSERT_EQ(j.exit_code, 0) << j.err;
  v1::Stats parsed;
  ASSERT_TRUE(pb::util::JsonStringToMessage(j.out, &parsed).ok()) << j.out;
  EXPECT_TRUE(pb::util::MessageDifferencer::Equals(parsed, service_.stats)) << j.out;
  EXPECT_NE(j.out.find("\"clouds_in_map\""), std::string::npos) << j.out;
}

// Every command's --json output: each stdout line one JSON document of the documented type.
TEST_F(FusionctlCallsTest, JsonIsParseableForEveryCommand) {
  service_.box_pages.resize(1);
  service_.box_pages[0].add_voxels()->set_size_m(0.1);
  service_.planes.add_planes()->set_d_m(1.75);
  const std::string bt = TempPath("map.bt"), png = TempPath("map.png");
  struct Case {
    std::vector<std::string> args;
    std::function<pb::Message*()> make;
    std::size_t documents;
  };
  const std::vector<Case> cases = {
      {{"health"}, [] { return new grpc::health::v1::HealthCheckResponse; }, 1},
      {{"stats"}, [] { return new v1::Stats; }, 1},
      {{"sensors"}, [] { return new v1::ListSensorsResponse; }, 1},
      {{"points", "1,2,3", "4,5,6"}, [] { return new v1::QueryPointsResponse; }, 1},
      {{"box", "0", "0", "0", "1", "1", "1"}, [] { return new v1::QueryBoxResponse; }, 1},
      {{"ray", "0", "0", "0", "1", "0", "0"}, [] { return new v1::CastRayResponse; }, 1},
      {{"planes"}, [] { return new v1::FindPlanesResponse; }, 1},
      {{"beam", "sr", "1", "2"}, [] { return new v1::InspectBeamResponse; }, 1},
      {{"reset"}, [] { return new v1::ResetMapResponse; }, 1},
      {{"clear-box", "0", "0", "0", "1", "1", "1"}, [] { return new v1::ClearBoxResponse; }, 1},
      {{"save"}, [] { return new v1::SaveMapResponse; }, 1},
      {{"watch", "--count", "2"}, [] { return new v1::MapUpdate; }, 2},
      {{"snapshot", bt}, [] { return new pb::Struct; }, 1},
      {{"render", png, "--size", "32x24"}, [] { return new pb::Struct; }, 1},
  };
  for (const auto& c : cases) {
    auto args = c.args;
    args.insert(args.begin(), "--json");
    const auto r = Fusionctl(args);
    ASSERT_EQ(r.exit_code, 0) << c.args[0] << ": " << r.err;
    const auto lines = Lines(r.out);
    EXPECT_EQ(lines.size(), c.documents) << c.args[0] << ":\n" << r.out;
    for (const auto& line : lines) {
      std::unique_ptr<pb::Message> message(c.make());
      const auto s = pb::util::JsonStringToMessage(line, message.get());
      EXPECT_TRUE(s.ok()) << c.args[0] << ": " << s.ToString() << "\n" << line;
    }
  }
  const auto snapshot = Fusionctl({"--json", "snapshot", bt});
  pb::Struct doc;
  ASSERT_TRUE(pb::util::JsonStringToMessage(snapshot.out, &doc).ok());
  EXPECT_EQ(doc.fields().at("path").string_value(), bt);
  EXPECT_EQ(doc.fields().at("format").string_value(), "bt");
  EXPECT_EQ(doc.fields().at("map_version").number_value(), 3);
  EXPECT_EQ(doc.fields().at("bytes").number_value(), std::filesystem::file_size(bt));
  const auto render = Fusionctl({"--json", "render", png, "--size", "32x24"});
  ASSERT_TRUE(pb::util::JsonStringToMessage(render.out, &doc).ok());
  EXPECT_EQ(doc.fields().at("width_px").number_value(), 32);
  EXPECT_EQ(doc.fields().at("height_px").number_value(), 24);
  EXPECT_EQ(doc.fields().at("voxels_drawn").number_value(), 1);
  std::filesystem::remove(bt);
  std::filesystem::remove(png);
}

TEST_F(FusionctlCallsTest, BoxSummaryCountsWhatItPrints) {
  service_.box_pages.resize(2);
  for (int page = 0; page < 2; ++page) {
    for (int i = 0; i < 4; ++i) {
      auto* v = service_.box_pages[page].add_voxels();
      v->set_state(i % 2 ? v1::VOXEL_STATE_FREE : v1::VOXEL_STATE_OCCUPIED);
      v->set_size_m(0.1);
    }
  }
  service_.box_pages[0].set_next_page_token("1");
  const std::vector<std::string> box = {"box", "0", "0", "0", "1", "1", "1"};
  auto args = box;
  args.insert(args.end(), {"--limit", "5"});
  auto r = Fusionctl(args);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(Lines(r.out).size(), 5u) << r.out;
  EXPECT_NE(r.err.find("# 5 voxels, 2 free, 3 occupied (limit reached)"), std::string::npos)
      << r.err;

  r = Fusionctl(box);
  EXPECT_EQ(Lines(r.out).size(), 8u) << r.out;
  EXPECT_NE(r.err.find("# 8 voxels, 4 free, 4 occupied\n"), std::string::npos) << r.err;

  args = box;
  args.insert(args.end(), {"--limit", "4", "--json"});
  r = Fusionctl(args);
  v1::QueryBoxResponse gathered;
  ASSERT_TRUE(pb::util::JsonStringToMessage(r.out, &gathered).ok()) << r.out;
  EXPECT_EQ(gathered.voxels_size(), 4);
  EXPECT_NE(r.err.find("# 4 voxels"), std::string::npos) << r.err;
}

TEST_F(FusionctlCallsTest, ClearBoxSendsTheBoxAndReportsWhatWasForgotten) {
  const auto r = Fusionctl({"clear-box", "-1.5", "0", "0.25", "2", "3", "4.5"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, "box cleared: 1234 voxels forgotten, version 2\n");
  const v1::ClearBoxRequest& q = service_.last_clear_box;
  EXPECT_EQ(q.min().x(), -1.5);
  EXPECT_EQ(q.min().z(), 0.25);
  EXPECT_EQ(q.max().y(), 3.0);
  EXPECT_EQ(q.max().z(), 4.5);
  EXPECT_EQ(Fusionctl({"clear-box", "0", "0", "0", "1", "1"}).exit_code, 2) << "five numbers";
  EXPECT_EQ(Fusionctl({"clear-box", "0", "0", "0", "1", "1", "x"}).exit_code, 2);
}

TEST_F(FusionctlCallsTest, ErrorsNameTheStatusAndCarryTheDetail) {
  service_.points_status =
      grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "point 0 is not finite");
  const auto r = Fusionctl({"points", "1,2,3"});
  EXPECT_EQ(r.exit_code, fusion::clients::kExitFailure);
  EXPECT_NE(r.err.find("INVALID_ARGUMENT"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("point 0 is not finite"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("(status"), std::string::npos) << r.err;
}

TEST_F(FusionctlCallsTest, DeadlineIsReportedAsADeadline) {
  service_.ray_delay = std::chrono::milliseconds(1500);
  const auto r = Fusionctl({"--timeout", "0.2", "ray", "0", "0", "0", "1", "0", "0"});
  EXPECT_EQ(r.exit_code, fusion::clients::kExitFailure);
  EXPECT_NE(r.err.find("deadline exceeded"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("within 0.2 s"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("cannot reach"), std::string::npos) << r.err;
}

// A TCP socket bound on 127.0.0.1 (an ephemeral port), listening or not; closed at the end.
class LoopbackSocket {
 public:
  explicit LoopbackSocket(bool listening) : fd_(socket(AF_INET, SOCK_STREAM, 0)) {
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t length = sizeof addr;
    if (fd_ < 0 || bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 ||
        (listening && listen(fd_, 4) != 0) ||
        getsockname(fd_, reinterpret_cast<sockaddr*>(&addr), &length) != 0) {
      ADD_FAILURE() << "no loopback socket";
      return;
    }
    address_ = "127.0.0.1:" + std::to_string(ntohs(addr.sin_port));
  }
  ~LoopbackSocket() {
    if (fd_ >= 0) close(fd_);
  }
  const std::string& address() const { return address_; }

 private:
  int fd_;
  std::string address_;
};

// A listening socket that never speaks HTTP/2: the call waits for the handshake until its
// deadline, which is a deadline, not an unreachable service.
TEST(FusionctlSilentServerTest, DeadlineIsReportedAsADeadline) {
  const LoopbackSocket silent(/*listening=*/true);
  const auto r = testing::RunFusionctl({"--server", silent.address(), "--timeout", "0.5", "stats"});
  EXPECT_EQ(r.exit_code, fusion::clients::kExitFailure);
  EXPECT_NE(r.err.find("deadline exceeded"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("DEADLINE_EXCEEDED"), std::string::npos) << r.err;
}

TEST(FusionctlUnreachableTest, ClosedPortIsReportedAsUnreachable) {
  // Bound, never listening: connections are refused.
  const LoopbackSocket closed(/*listening=*/false);
  const auto r = testing::RunFusionctl({"--server", closed.address(), "--timeout", "5", "stats"});
  EXPECT_EQ(r.exit_code, fusion::clients::kExitFailure);
  EXPECT_NE(r.err.find("cannot reach fusiond at " + closed.address()), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("UNAVAILABLE"), std::string::npos) << r.err;
}

TEST_F(FusionctlCallsTest, RenderRefusesAnExtensionItCannotWrite) {
  for (const std::string name : {"map.jpg", "map.jpeg", "map", "map.png.txt"}) {
    const std::string path = TempPath(name);
    const auto r = Fusionctl({"render", path});
    EXPECT_EQ(r.exit_code, fusion::clients::kExitUsage) << name;
    EXPECT_NE(r.err.find(".png"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(path)) << name;
  }
  EXPECT_EQ(service_.calls, 0);  // refused before asking for the map
  const std::string png = TempPath("MAP.PNG");
  const auto r = Fusionctl({"render", png, "--size", "16x16"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  std::ifstream in(png, std::ios::binary);
  char magic[4] = {};
  in.read(magic, 4);
  EXPECT_EQ(std::string(magic + 1, 3), "PNG");
  std::filesystem::remove(png);
}

TEST_F(FusionctlCallsTest, UsageErrorsCallNothing) {
  EXPECT_EQ(Fusionctl({"reset", "--yes-really"}).exit_code, fusion::clients::kExitUsage);
  EXPECT_EQ(Fusionctl({"save", "now"}).exit_code, fusion::clients::kExitUsage);
  EXPECT_EQ(service_.calls, 0);
}

TEST_F(FusionctlCallsTest, PlanesShowATenthOfADegreeTilt) {
  // Normals 0.1 degree apart around the x axis: they must print differently.
  for (const double tilt_deg : {0.0, 0.1}) {
    auto* p = service_.planes.add_planes();
    const double t = tilt_deg * M_PI / 180.0;
    p->set_phi_deg(tilt_deg);
    p->set_theta_deg(90.0);
    p->mutable_normal()->set_x(std::cos(t));
    p->mutable_normal()->set_y(std::sin(t));
  }
  service_.planes.mutable_planes(1)->set_phi_deg(0.01);  // the angle column: 0.01 degree
  const auto r = Fusionctl({"planes"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("( 1.000000, 0.000000, 0.000000)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("( 0.999998, 0.001745, 0.000000)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("    0.01     90.00"), std::string::npos) << r.out;
}

TEST_F(FusionctlCallsTest, BearerTokenGoesWithEveryCall) {
  const std::string token_file = TempPath("token");
  std::ofstream(token_file) << "  s3cret \nignored\n";
  const std::string bt = TempPath("map.ot");
  for (const std::vector<std::string>& args : {std::vector<std::string>{"stats"},
                                               {"points", "1,2,3"},
                                               {"snapshot", bt},
                                               {"watch", "--count", "1"}}) {
    auto with_token = args;
    with_token.insert(with_token.begin(), {"--token-file", token_file});
    EXPECT_EQ(Fusionctl(with_token).exit_code, 0) << args[0];
  }
  setenv("FUSION_TOKEN_FILE", token_file.c_str(), 1);
  EXPECT_EQ(Fusionctl({"reset"}).exit_code, 0);
  unsetenv("FUSION_TOKEN_FILE");
  const auto sent = service_.Authorizations();
  ASSERT_EQ(sent.size(), 5u);
  for (const auto& a : sent) EXPECT_EQ(a, "Bearer s3cret");

  EXPECT_EQ(Fusionctl({"stats"}).exit_code, 0);
  EXPECT_EQ(service_.Authorizations().back(), "");  // no token file: no metadata

  std::filesystem::remove(token_file);
  const auto r = Fusionctl({"--token-file", token_file, "stats"});
  EXPECT_EQ(r.exit_code, fusion::clients::kExitFailure);
  EXPECT_NE(r.err.find(token_file), std::string::npos) << r.err;
  std::filesystem::remove(bt);
}

}  // namespace
}  // namespace fusionctl
