// fusion-calibrate as a process: a recording of simulated STOC clouds of a board seen from 1, 2
// and 3 m, the tool's stdout parsed back as a fusiond configuration, its errors.
#include <google/protobuf/text_format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "../../support/subprocess.h"
#include "fusion/clients/importers.h"
#include "fusion/clients/recording.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"
#include "fusion/v1/config.pb.h"

namespace {

using std::chrono::milliseconds;

constexpr double kBoardXM = 3.5;  // the board's plane x = 3.5 in the world

std::string TempPath(const std::string& name) {
  return ::testing::TempDir() + "/calibrate_tool_" + std::to_string(getpid()) + "_" + name;
}

struct Result {
  int code = -1;
  std::string out, err;
};

// RunTool: fusion-calibrate with the arguments (through sh, to keep stderr apart from stdout).
Result RunTool(const std::string& args) {
  const std::string err_path = TempPath("stderr.txt");
  const std::string command =
      std::string(FUSION_BINARY_DIR) + "/clients/fusion-calibrate " + args + " 2>" + err_path;
  fusion::testing::Subprocess process({"/bin/sh", "-c", command});
  Result r;
  if (!process.started()) return r;
  process.WaitForOutput("(?!)", std::chrono::seconds(120));  // drains stdout until the exit
  r.code = process.Wait(milliseconds(5000));
  r.out = process.output();
  std::ifstream in(err_path);
  std::stringstream text;
  text << in.rdbuf();
  r.err = text.str();
  return r;
}

// A STOC (64 x 48 beams) facing a large board at x = 3.5 m from x = 2.5, 1.5 and 0.5 m, four
// frames each, as the recording fusion-record would have written.
const std::string& Recording() {
  static const std::string path = [] {
    const std::string file = TempPath("stoc.frec");
    std::unique_ptr<fusion::clients::RecordingWriter> writer;
    EXPECT_TRUE(
        fusion::clients::RecordingWriter::Create(file, "calibrate_tool_test", "sim", &writer).ok());
    fusion::sim::Scene scene;
    fusion::sim::Rectangle board;
    board.center_m = Eigen::Vector3d(kBoardXM, 0, 0);
    board.axis_u = Eigen::Vector3d::UnitY();
    board.axis_v = Eigen::Vector3d::UnitZ();
    board.half_u_m = board.half_v_m = 5.0;
    scene.AddRectangle(board);
    fusion::sim::SimOptions options;
    options.flag_beyond_range = false;
    fusion::sim::RangeSimulator simulator(
        scene, fusion::sim::WithTessellation(*fusion::SensorPreset("stoc"), 64, 48), options);
    std::uint64_t sequence = 0;
    for (double distance_m : {1.0, 2.0, 3.0}) {
      const Eigen::Isometry3d T_world_sensor =
          fusion::sim::ForwardLookingPose(Eigen::Vector3d(kBoardXM - distance_m, 0, 0));
      const Eigen::Quaterniond q(T_world_sensor.rotation());
      for (int f = 0; f < 4; ++f) {
        const fusion::sim::OrganizedCloud cloud = simulator.Capture(T_world_sensor);
        fusion::v1::RecordedCloud recorded;
        fusion::clients::SetIdentity("stoc_left", sequence, 1.7e9 + 0.2 * sequence, "sim",
                                     &recorded);
        ++sequence;
        recorded.set_width(static_cast<std::uint32_t>(cloud.cols));
        recorded.set_height(static_cast<std::uint32_t>(cloud.rows));
        auto* pose = recorded.mutable_t_world_sensor();
        pose->set_tx(T_world_sensor.translation().x());
        pose->set_ty(T_world_sensor.translation().y());
        pose->set_tz(T_world_sensor.translation().z());
        pose->set_qx(q.x()), pose->set_qy(q.y()), pose->set_qz(q.z()), pose->set_qw(q.w());
        for (std::size_t i = 0; i < cloud.size(); ++i) {
          fusion::clients::AppendPoint(cloud.xyz[3 * i], cloud.xyz[3 * i + 1], cloud.xyz[3 * i + 2],
                                       &recorded);
        }
        EXPECT_TRUE(writer->Append(recorded).ok());
      }
    }
    EXPECT_TRUE(writer->Close().ok());
    return file;
  }();
  return path;
}

fusion::v1::SensorConfig Parse(const std::string& out) {
  fusion::v1::ServiceConfig config;
  EXPECT_TRUE(google::protobuf::TextFormat::ParseFromString(out, &config)) << out;
  EXPECT_EQ(config.sensors_size(), 1) << out;
  return config.sensors_size() > 0 ? config.sensors(0) : fusion::v1::SensorConfig();
}

double Eval(const fusion::v1::Polynomial2& p, double t) {
  return (p.a2() * t + p.a1()) * t + p.a0();
}

TEST(CalibrateTool, FitsTheStereoModelFromARecording) {
  const std::string plot = TempPath("plot.png");
  const Result r = RunTool(Recording() + " --sensor-id stoc_left --plane 1,0,0,-3.5 --preset stoc" +
                           " --plot " + plot);
  ASSERT_EQ(r.code, 0) << r.err;
  // stdout is the sensors block and nothing else.
  EXPECT_EQ(r.out.rfind("sensors {", 0), 0u) << r.out;
  const fusion::v1::SensorConfig c = Parse(r.out);
  EXPECT_EQ(c.id(), "stoc_left");
  EXPECT_EQ(c.preset(), "stoc");
  EXPECT_EQ(c.model(), "paper3d");
  EXPECT_FALSE(c.has_fov_h_deg());
  EXPECT_FALSE(c.has_cols());
  const fusion::SensorSpec truth = *fusion::SensorPreset("stoc");
  for (double t : {1.0, 1.5, 2.0, 2.5, 3.0, 3.5}) {
    EXPECT_NEAR(Eval(c.q_mu(), t), truth.q_mu(t), 0.005) << t;
    EXPECT_NEAR(Eval(c.q_sigma(), t), truth.q_sigma(t), 0.15 * truth.q_sigma(t)) << t;
  }
  EXPECT_NEAR(c.r_min_m(), 1.0, 0.01);
  EXPECT_NEAR(c.r_max_m(), 3.0 / std::cos(0.67), 0.1);  // the far board's corners
  EXPECT_GE(c.epsilon(), 1e-4);
  EXPECT_LT(c.epsilon(), 0.01);  // the simulator draws no outliers
  // stderr: the plane, the table, eps and the log-likelihood.
  EXPECT_NE(r.err.find("target plane (world frame) 1.000000,0.000000,0.000000,-3.500000"),
            std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("fit sigma"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("log-likelihood"), std::string::npos) << r.err;
  // The plot is a PNG.
  std::ifstream png(plot, std::ios::binary);
  char magic[8] = {};
  png.read(magic, 8);
  EXPECT_EQ(std::string(magic + 1, 3), "PNG");
}

TEST(CalibrateTool, WithoutAPlaneFitsTheDominantNearPlane) {
  // The nearest board (1 m, read as ~1.07 m by the biased stereo camera) gives the plane.
  const Result r = RunTool(Recording() + " --sensor-id stoc_left --near 1.5 --degree 1");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("no --plane: fitted the dominant plane"), std::string::npos) << r.err;
  const fusion::v1::SensorConfig c = Parse(r.out);
  EXPECT_EQ(c.q_mu().a2(), 0.0);
  EXPECT_EQ(c.q_sigma().a2(), 0.0);
  EXPECT_TRUE(c.preset().empty());
  // Against a plane that is itself read ~8 cm too far the offset is off, but the slope is
  // still the stereo camera's 1.15.
  EXPECT_NEAR(c.q_mu().a1(), fusion::SensorPreset("stoc")->q_mu.a1, 0.03);
}

TEST(CalibrateTool, PlanePerCloudHidesABiasCommonToTheCloud) {
  // Each cloud's own plane lies where that cloud reads the board: the stereo bias (7 to 37 cm
  // here) is absorbed, what is left is the spread and the bias's variation across the view.
  const Result r = RunTool(Recording() + " --sensor-id stoc_left --near 10 --plane-per-cloud");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("cloud 12: plane "), std::string::npos) << r.err;
  const fusion::v1::SensorConfig c = Parse(r.out);
  const fusion::SensorSpec truth = *fusion::SensorPreset("stoc");
  for (double t : {1.2, 2.0, 3.0}) {
    EXPECT_LT(std::abs(Eval(c.q_mu(), t) - t), 0.03) << t;
    // Near, the bias's variation across the view (1.7 cm at 1 m) outgrows the 3 mm sigma.
    if (t >= 2.0) {
      EXPECT_NEAR(Eval(c.q_sigma(), t), truth.q_sigma(t), 0.3 * truth.q_sigma(t)) << t;
    }
  }
}

TEST(CalibrateTool, LocalPatchKeepsTheBiasAndTakesTheNoiseFromLocalPlanes) {
  const std::string args = Recording() + " --sensor-id stoc_left --plane 1,0,0,-3.5";
  const Result plain = RunTool(args);
  const Result r = RunTool(args + " --local-patch 0.4");  // 64 x 48 beams: wide cells
  ASSERT_EQ(plain.code, 0) << plain.err;
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("--local-patch 0.400: "), std::string::npos) << r.err;
  const fusion::v1::SensorConfig p = Parse(plain.out), c = Parse(r.out);
  EXPECT_EQ(c.q_mu().DebugString(), p.q_mu().DebugString());  // the bias: the target plane's
  EXPECT_EQ(c.r_max_m(), p.r_max_m());
  const fusion::SensorSpec truth = *fusion::SensorPreset("stoc");
  for (double t : {1.0, 2.0, 3.0}) {
    EXPECT_NEAR(Eval(c.q_sigma(), t), truth.q_sigma(t), 0.15 * truth.q_sigma(t)) << t;
  }
}

TEST(CalibrateTool, Help) {
  const Result r = RunTool("--help");
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.out.find("Usage: fusion-calibrate RECORDING.frec..."), std::string::npos);
}

TEST(CalibrateTool, ClearErrors) {
  struct Case {
    std::string args;
    int code;
    std::string message;
  };
  const std::string rec = Recording();
  const std::vector<Case> cases = {
      {"/nonexistent.frec --sensor-id x", 1, "reading /nonexistent.frec"},
      {rec + " --sensor-id nope", 1,
       "unknown sensor id 'nope': the recordings hold clouds of "
       "stoc_left"},
      {rec + " --sensor-id stoc_left --plane 1,0,0,-3.5 --r-min 10 --r-max 20", 1,
       "too few samples on the target: 0"},
      {rec + " --sensor-id stoc_left --plane 0,0,1,-100", 1, "no target found"},
      {rec + " --sensor-id stoc_left --near 0.2", 1, "no target found: only 0 candidate points"},
      {rec + " --sensor-id stoc_left --plane 1,0,0,-3.5 --r-min 1.9 --r-max 2.4", 1,
       "degenerate range spread"},
      {rec + " --sensor-id stoc_left --degree 3", 2, "--degree must be 0, 1 or 2"},
      {rec + " --sensor-id stoc_left --plane 1,0,0", 2, "--plane: expected 4"},
      {rec + " --sensor-id stoc_left --preset nosuch", 2, "'nosuch' is not a preset"},
      {rec + " --sensor-id stoc_left --local-patch 0", 2, "--local-patch must be > 0"},
      {rec, 2, "--sensor-id is required"},
      {rec + " --sensor-id stoc_left --plane 1,0,0,-3.5 --plane-per-cloud", 2, "leave out"},
  };
  for (const Case& c : cases) {
    const Result r = RunTool(c.args);
    EXPECT_EQ(r.code, c.code) << c.args << "\n" << r.err;
    EXPECT_NE(r.err.find(c.message), std::string::npos) << c.args << "\n" << r.err;
    EXPECT_TRUE(r.out.empty()) << c.args << "\n" << r.out;
  }
  // The degenerate spread names the way out.
  const Result narrow =
      RunTool(rec + " --sensor-id stoc_left --plane 1,0,0,-3.5 --r-min 1.9 " + "--r-max 2.4");
  EXPECT_NE(narrow.err.find("lower degree (--degree 0)"), std::string::npos) << narrow.err;
}

TEST(CalibrateTool, FitPlaneOnlyPrintsThePlane) {
  const Result r = RunTool(Recording() + " --sensor-id stoc_left --near 1.5 --fit-plane-only");
  ASSERT_EQ(r.code, 0) << r.err;
  double a = 0, b = 0, c = 0, d = 0;
  ASSERT_EQ(std::sscanf(r.out.c_str(), "%lf,%lf,%lf,%lf", &a, &b, &c, &d), 4) << r.out;
  EXPECT_NEAR(a, 1.0, 1e-3);
  EXPECT_NEAR(-d, kBoardXM + 0.08, 0.02);  // the biased reading of the nearest board
}

TEST(CalibrateTool, KinectOnTheTumFloor) {
  // The real depth camera (docs/sensors.md, "Calibrating a sensor"): the floor of the TUM
  // sequence, fitted from the ground-truth-posed points near z = 0, as the reference.
  const std::string data = std::string(FUSION_SHARED_DATA_DIR) + "/tum_fr2_pioneer_slam2";
  if (!std::filesystem::exists(data + "/groundtruth.txt")) {
    GTEST_SKIP() << "no real data: " << data << " is missing";
  }
  const std::string rec = TempPath("tum.frec");
  fusion::testing::Subprocess import(
      {std::string(FUSION_BINARY_DIR) + "/clients/fusion-import", "tum", data, "-o", rec});
  import.WaitForOutput("(?!)", std::chrono::seconds(120));
  ASSERT_EQ(import.Wait(milliseconds(5000)), 0) << import.output();
  const Result plane = RunTool(rec + " --sensor-id tum --near 10 --plane-z-band -0.15,0.15 " +
                               "--max-points 100000 --fit-plane-only");
  ASSERT_EQ(plane.code, 0) << plane.err;
  double a = 0, b = 0, c = 0, d = 0;
  ASSERT_EQ(std::sscanf(plane.out.c_str(), "%lf,%lf,%lf,%lf", &a, &b, &c, &d), 4) << plane.out;
  EXPECT_GT(c, std::cos(3.0 * M_PI / 180.0));  // a floor: within 3 degrees of level
  EXPECT_LT(std::abs(d), 0.15);                // near z = 0
  const std::string plane_arg = plane.out.substr(0, plane.out.find('\n'));
  const Result r = RunTool(rec + " --sensor-id tum --plane " + plane_arg + " --max-points 100000");
  ASSERT_EQ(r.code, 0) << r.err;
  const fusion::v1::SensorConfig k = Parse(r.out);
  // What the floor supports: about 1.2 to 2.9 m (nearer, the camera does not see the floor;
  // farther, the rays graze it). A Kinect reads nearly unbiased there, with centimetres of
  // spread (most of it the reference's: the poses' tilt errors, docs/sensors.md).
  EXPECT_NEAR(k.r_min_m(), 1.15, 0.1);
  EXPECT_NEAR(k.r_max_m(), 2.9, 0.2);
  for (double t : {1.5, 2.0, 2.5}) {
    EXPECT_LT(std::abs(Eval(k.q_mu(), t) - t), 0.1) << t;
    EXPECT_GT(Eval(k.q_sigma(), t), 0.005) << t;
    EXPECT_LT(Eval(k.q_sigma(), t), 0.1) << t;
  }
  EXPECT_LT(k.epsilon(), 0.05);
  // Against local planes (5 cm cells of the floor) the poses' tilt and the floor's warp drop
  // out: millimetres at 2 m (Khoshelham and Elberink 2012: about 6), not centimetres.
  const Result local = RunTool(rec + " --sensor-id tum --plane " + plane_arg +
                               " --max-points 100000 --local-patch 0.05");
  ASSERT_EQ(local.code, 0) << local.err;
  const fusion::v1::SensorConfig l = Parse(local.out);
  EXPECT_LT(Eval(l.q_sigma(), 2.0), 0.5 * Eval(k.q_sigma(), 2.0));
  EXPECT_GT(Eval(l.q_sigma(), 2.0), 0.003);
  EXPECT_LT(Eval(l.q_sigma(), 2.0), 0.010);
  std::filesystem::remove(rec);  // 37 MB
}

}  // namespace
