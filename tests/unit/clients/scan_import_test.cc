// Text scans (x y z, NODE lines) and OctoMap scan graphs: the real laser scan in
// ../shared/data (skipped when absent) and files written here.
#include <gtest/gtest.h>
#include <octomap/ScanGraph.h>

#include <cmath>
#include <string>
#include <vector>

#include "fusion/clients/importers.h"
#include "import_test_util.h"

namespace fusion::clients::import_test {
namespace {

TEST(ScanTest, RealLaserScanHas88206Points) {
  const std::string path = kData + "/octomap_laser_scan/scan.dat.bz2";
  if (!Exists(path)) GTEST_SKIP() << "OctoMap scan not found at " << path;
  fusion::v1::RecordedPose pose;
  pose.set_tz(0.5);
  pose.set_qw(1.0);
  std::vector<fusion::v1::RecordedCloud> clouds;
  const Status s = ReadXyzScan(path, pose, &clouds);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(clouds.size(), 1u);
  EXPECT_EQ(clouds[0].width(), 88206u);
  EXPECT_EQ(clouds[0].height(), 1u);
  EXPECT_EQ(clouds[0].t_world_sensor().tz(), 0.5);
  double max_range = 0, min_range = 1e9;
  for (std::size_t i = 0; i < 88206; ++i) {
    float p[3];
    GetPoint(clouds[0], i, p);
    const double r = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    max_range = std::max(max_range, r);
    min_range = std::min(min_range, r);
  }
  EXPECT_GT(min_range, 0.4);  // README: ranges 0.47-29 m
  EXPECT_LT(max_range, 30.0);
}

TEST(ScanTest, NodeLinesSplitCloudsAndBadLinesAreNamed) {
  const std::string path = TempPath("scan.txt");
  WriteFile(path, "# comment\nNODE 1 2 3 0 0 0\n0 0 1\n0 1 1\nNODE 0 0 0 0 0 1.5707963\n5 5 5\n");
  fusion::v1::RecordedPose pose;
  pose.set_qw(1.0);
  std::vector<fusion::v1::RecordedCloud> clouds;
  Status s = ReadXyzScan(path, pose, &clouds);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(clouds.size(), 2u);
  EXPECT_EQ(clouds[0].width(), 2u);
  EXPECT_EQ(clouds[0].t_world_sensor().ty(), 2.0);
  EXPECT_EQ(clouds[1].width(), 1u);
  EXPECT_NEAR(clouds[1].t_world_sensor().qz(), std::sqrt(0.5), 1e-6);

  WriteFile(path, "0 0 1\n0 x 1\n");
  s = ReadXyzScan(path, pose, &clouds);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find(":2:"), std::string::npos) << s.message();
  std::remove(path.c_str());
}

TEST(ScanGraphTest, GraphWrittenByOctoMapImports) {
  octomap::ScanGraph graph;
  for (int n = 0; n < 3; ++n) {
    auto* scan = new octomap::Pointcloud();  // the graph owns it
    for (int i = 0; i <= n; ++i)
      scan->push_back(1.0f + static_cast<float>(i), 0.0f, 0.5f * static_cast<float>(n));
    graph.addNode(scan, octomap::pose6d(static_cast<double>(n), 0, 0.25, 0, 0, 0.3 * n));
  }
  graph.connectPrevious();
  const std::string path = TempPath("three.graph");
  ASSERT_TRUE(graph.writeBinary(path));

  std::vector<fusion::v1::RecordedCloud> clouds;
  const Status s = ReadScanGraph(path, &clouds);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(clouds.size(), 3u);
  for (int n = 0; n < 3; ++n) {
    const auto& cloud = clouds[static_cast<std::size_t>(n)];
    EXPECT_EQ(cloud.width(), static_cast<std::uint32_t>(n + 1));
    EXPECT_NEAR(cloud.t_world_sensor().tx(), n, 1e-6);
    EXPECT_NEAR(cloud.t_world_sensor().tz(), 0.25, 1e-6);
    EXPECT_NEAR(cloud.t_world_sensor().qz(), std::sin(0.15 * n), 1e-6);
    EXPECT_NEAR(cloud.t_world_sensor().qw(), std::cos(0.15 * n), 1e-6);
    float p[3];
    GetPoint(cloud, static_cast<std::size_t>(n), p);
    EXPECT_FLOAT_EQ(p[0], 1.0f + static_cast<float>(n));
    EXPECT_FLOAT_EQ(p[2], 0.5f * static_cast<float>(n));
  }
  WriteFile(path, "garbage");
  EXPECT_FALSE(ReadScanGraph(path, &clouds).ok());
  EXPECT_FALSE(ReadScanGraph(TempPath("missing.graph"), &clouds).ok());
  std::remove(path.c_str());
}

}  // namespace
}  // namespace fusion::clients::import_test
