#include "fusion/core/world_map.h"

#include <algorithm>

#include "world_map_fixture.h"

namespace fusion {
namespace {

TEST_F(WorldMapTest, RejectsBadInput) {
  WorldMap map(options_);
  EXPECT_EQ(map.AddSensor("sr", spec_), MapStatus::kOk);
  EXPECT_EQ(map.AddSensor("sr", spec_), MapStatus::kDuplicateSensor);
  const auto cloud = Frame();
  EXPECT_EQ(Add(&map, "nope", pose_, cloud), MapStatus::kUnknownSensor);
  Eigen::Isometry3d bad = pose_;
  bad.translation().x() = std::nan("");
  EXPECT_EQ(Add(&map, "sr", bad, cloud), MapStatus::kInvalidPose);
  Eigen::Isometry3d scaled = pose_;
  scaled.linear() *= 2.0;
  EXPECT_EQ(Add(&map, "sr", scaled, cloud), MapStatus::kInvalidPose);
  EXPECT_EQ(map.Integrate("sr", pose_, nullptr, 3), MapStatus::kInvalidArgument);
  EXPECT_EQ(map.Integrate("sr", pose_, cloud.xyz.data(), cloud.size(), {1, 0}),
            MapStatus::kInvalidArgument);
  EXPECT_EQ(map.Render("nope"), MapStatus::kUnknownSensor);
  EXPECT_EQ(map.Commit("nope"), MapStatus::kUnknownSensor);
  EXPECT_EQ(map.version(), 0u);
  EXPECT_EQ(map.tree().size(), 0u);
  EXPECT_STREQ(MapStatusName(MapStatus::kInvalidPose), "invalid pose");
}

// OctoMap's keys cover +-32768 voxels: beyond, a voxel would wrap around to the far side.
TEST(MapExtent, InsideMapMatchesTheKeyRange) {
  EXPECT_DOUBLE_EQ(MapHalfExtentM(0.02), 655.36);
  EXPECT_TRUE(InsideMap({655.35, -655.36, 0.0}, 0.02));
  EXPECT_FALSE(InsideMap({655.37, 0.0, 0.0}, 0.02));
  EXPECT_FALSE(InsideMap({0.0, -655.37, 0.0}, 0.02));
  EXPECT_FALSE(InsideMap({0.0, 0.0, std::nan("")}, 0.02));
  octomap::OcTree tree(0.02);
  octomap::OcTreeKey key;
  EXPECT_TRUE(tree.coordToKeyChecked(octomap::point3d(655.35f, -655.36f, 0.0f), key));
  EXPECT_EQ(key, KeyOfPoint({655.35, -655.36, 0.0}, 0.02));
}

// A pose beyond the keys is refused with nothing touched; near the edge, readings beyond it are
// left out and counted, and the render's rays stop at the edge instead of wrapping around.
TEST_F(WorldMapTest, NothingOutsideTheMapIsWrittenOrWrapped) {
  for (const RenderMethod method : {RenderMethod::kProjective, RenderMethod::kRayTraced}) {
    SCOPED_TRACE(method == RenderMethod::kProjective ? "projective" : "ray-traced");
    options_.render.method = method;
    ExpectNothingOutsideTheMap();
  }
}

}  // namespace

void WorldMapTest::ExpectNothingOutsideTheMap() {
  WorldMap map(options_);
  ASSERT_EQ(map.AddSensor("sr", spec_), MapStatus::kOk);
  const double half = MapHalfExtentM(kRes);
  const BeamTessellation tess(spec_);
  // Every even beam reads a surface at 0.995 m (the edge is 1 m ahead: the reading's
  // distribution runs past it), every odd one 2.5 m (beyond the edge), and the last row nothing
  // within range.
  std::vector<float> xyz;
  std::vector<std::uint8_t> beyond;
  std::size_t beyond_edge = 0;
  for (std::size_t b = 0; b < tess.beam_count(); ++b) {
    const bool last_row = b >= tess.beam_count() - static_cast<std::size_t>(tess.cols());
    const double range = last_row ? spec_.r_max_m : (b % 2 == 0 ? 0.995 : 2.5);
    const Eigen::Vector3d p = range * tess.Direction(b);
    xyz.insert(xyz.end(), {float(p.x()), float(p.y()), float(p.z())});
    beyond.push_back(last_row ? 1 : 0);
    beyond_edge += !last_row && b % 2 == 1;
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();  // z -> x
  T.translation() = Eigen::Vector3d(half + 5.0, 0.0, 0.0);
  EXPECT_EQ(map.Integrate("sr", T, xyz.data(), tess.beam_count(), beyond), MapStatus::kOutsideMap);
  EXPECT_EQ(map.version(), 0u);
  EXPECT_EQ(map.Counters("sr")->frames_integrated, 0u);
  T.translation() = Eigen::Vector3d(half - 1.0, 0.0, 0.0);
  IntegrationStats stats;
  ASSERT_EQ(map.Integrate("sr", T, xyz.data(), tess.beam_count(), beyond, &stats), MapStatus::kOk);
  EXPECT_EQ(stats.rejected_outside_map, beyond_edge);
  EXPECT_EQ(stats.updated, tess.beam_count() - beyond_edge - tess.cols());
  EXPECT_EQ(map.Counters("sr")->points_rejected, beyond_edge);
  ASSERT_EQ(map.Render("sr"), MapStatus::kOk);
  std::size_t leaves = 0, at_edge = 0;
  for (auto it = map.tree().begin_leafs(); it != map.tree().end_leafs(); ++it) {
    ++leaves;
    const double x_lo = it.getX() - 0.5 * it.getSize();
    EXPECT_GT(x_lo, half - 1.0 - it.getSize()) << "a voxel behind the sensor or wrapped around";
    EXPECT_LE(it.getX() + 0.5 * it.getSize(), half + 1e-6);
    at_edge += it.getX() > half - 0.1;
  }
  EXPECT_GT(leaves, 100u);
  EXPECT_GT(at_edge, 0u) << "the free space of the beyond-range beams runs up to the edge";
}

namespace {

TEST_F(WorldMapTest, RenderingTheSamePeriodTwiceLeavesTheMapUnchanged) {
  WorldMap map(options_);
  ASSERT_EQ(map.AddSensor("sr", spec_), MapStatus::kOk);
  for (int i = 0; i < 5; ++i) ASSERT_EQ(Add(&map, "sr", pose_, Frame()), MapStatus::kOk);
  ASSERT_EQ(map.Render("sr"), MapStatus::kOk);
  const std::uint64_t version = map.version();
  EXPECT_EQ(version, 1u);
  octomap::OcTree before(map.tree());
  FuseStats stats;
  ASSERT_EQ(map.Render("sr", &stats), MapStatus::kOk);
  EXPECT_EQ(stats.regions_changed, 0u);
  EXPECT_EQ(map.version(), version);
  ExpectSameLeaves(before, map.tree());
  EXPECT_EQ(map.Publish().changes.version, version);  // nothing new to publish
}

TEST_F(WorldMapTest, ReRenderReplacesThePeriodInsteadOfAddingIt) {
  std::vector<sim::OrganizedCloud> frames;
  for (int i = 0; i < 6; ++i) frames.push_back(Frame());
  WorldMap incremental(options_);
  WorldMap once(options_);
  ASSERT_EQ(incremental.AddSensor("sr", spec_), MapStatus::kOk);
  ASSERT_EQ(once.AddSensor("sr", spec_), MapStatus::kOk);
  for (const auto& f : frames) {
    ASSERT_EQ(Add(&incremental, "sr", pose_, f), MapStatus::kOk);
    ASSERT_EQ(incremental.Render("sr"),
              MapStatus::kOk);  // a render after every frame
    ASSERT_EQ(Add(&once, "sr", pose_, f), MapStatus::kOk);
  }
  ASSERT_EQ(once.Render("sr"), MapStatus::kOk);
  ExpectSameLeaves(incremental.tree(), once.tree());
  EXPECT_EQ(incremental.Counters("sr")->renders, 6u);
  EXPECT_EQ(incremental.Counters("sr")->commits, 0u);
}

TEST_F(WorldMapTest, MovingBeyondToleranceCommitsAndRestarts) {
  WorldMap map(options_);
  ASSERT_EQ(map.AddSensor("sr", spec_), MapStatus::kOk);
  bool committed = true;
  ASSERT_EQ(Add(&map, "sr", pose_, Frame(), &committed), MapStatus::kOk);
  EXPECT_FALSE(committed);
  // Within tolerance (5 mm, 0.3 degrees): same period.
  Eigen::Isometry3d nudged = pose_;
  nudged.translation().y() += 0.005;
  nudged.linear() = nudged.linear() * Eigen::AngleAxisd(0.005, Eigen::Vector3d::UnitY()).matrix();
  ASSERT_EQ(Add(&map, "sr", nudged, Frame(), &committed), MapStatus::kOk);
  EXPECT_FALSE(committed);
  EXPECT_EQ(map.Counters("sr")->frames_in_period, 2u);
  // Not yet rendered: the map is empty. The move commits (rendering the stale
  // period first).
  EXPECT_EQ(map.tree().size(), 0u);
  Eigen::Isometry3d moved = pose_;
  moved.translation().x() += 0.3;
  ASSERT_EQ(Add(&map, "sr", moved, simulator_.Capture(moved), &committed), MapStatus::kOk);
  EXPECT_TRUE(committed);
  const auto counters = *map.Counters("sr");
  EXPECT_EQ(counters.commits, 1u);
  EXPECT_EQ(counters.pose_moves, 1u);
  EXPECT_EQ(counters.frames_in_period, 1u);
  EXPECT_EQ(counters.frames_integrated, 3u);
  // The committed period is in the map; the board voxel seen from the first
  // pose is occupied.
  const auto board = map.Occupancy(Eigen::Vector3d(1.75, 0.01, 0.01));
  ASSERT_TRUE(board.has_value());
  EXPECT_GT(*board, 0.5);
  const octomap::OcTree committed_only(map.tree());
  // Rendering the new period adds to (does not replace) the committed one.
  ASSERT_EQ(map.Render("sr"), MapStatus::kOk);
  EXPECT_GT(*map.Occupancy(Eigen::Vector3d(1.75, 0.01, 0.01)), *board);
  EXPECT_GE(map.tree().getNumLeafNodes(), committed_only.getNumLeafNodes());
}

// The share of `from`'s occupied leaves with an occupied node of `to` within one voxel (the
// 26-neighbourhood).
double OccupiedNear(const octomap::OcTree& from, const octomap::OcTree& to) {
  std::size_t occupied = 0, near = 0;
  for (auto it = from.begin_leafs(); it != from.end_leafs(); ++it) {
    if (it->getLogOdds() <= 0.0f) continue;
    ++occupied;
    const octomap::OcTreeKey k = it.getKey();
    bool found = false;
    for (int dx = -1; dx <= 1 && !found; ++dx) {
      for (int dy = -1; dy <= 1 && !found; ++dy) {
        for (int dz = -1; dz <= 1 && !found; ++dz) {
          const auto* n = to.search(octomap::OcTreeKey(static_cast<octomap::key_type>(k[0] + dx),
                                                       static_cast<octomap::key_type>(k[1] + dy),
                                                       static_cast<octomap::key_type>(k[2] + dz)));
          found = n != nullptr && n->getLogOdds() > 0.0f;
        }
      }
    }
    near += found ? 1 : 0;
  }
  return occupied > 0 ? static_cast<double>(near) / static_cast<double>(occupied) : 0.0;
}

// A cloud taken within the tolerance of the period's pose, but not at it, is mapped where its
// points were measured: its points go into the period's sensor frame. Turned 0.9 degrees (the
// tolerance is 1), the board 1.75 m ahead would otherwise come out 2.7 cm aside.
TEST_F(WorldMapTest, ACloudWithinTheToleranceIsMappedWhereItWasTaken) {
  Eigen::Isometry3d turned = pose_;
  turned.linear() =
      turned.linear() * Eigen::AngleAxisd(0.9 * M_PI / 180.0, Eigen::Vector3d::UnitY()).matrix();
  const auto cloud = simulator_.Capture(turned);
  // The period opens at pose_ with a cloud of missing readings (no evidence), then takes the
  // turned cloud.
  sim::OrganizedCloud nothing = cloud;
  std::fill(nothing.xyz.begin(), nothing.xyz.end(), 0.0f);
  std::fill(nothing.beyond_range.begin(), nothing.beyond_range.end(), std::uint8_t{0});
  options_.resolution_m = 0.02;
  WorldMap via_period(options_);
  ASSERT_EQ(via_period.AddSensor("sr", spec_), MapStatus::kOk);
  ASSERT_EQ(Add(&via_period, "sr", pose_, nothing), MapStatus::kOk);
  ASSERT_EQ(Add(&via_period, "sr", turned, cloud), MapStatus::kOk);
  EXPECT_EQ(via_period.Counters("sr")->frames_in_period, 2u) << "within the tolerance";
  ASSERT_EQ(via_period.Render("sr"), MapStatus::kOk);
  // The same cloud in a period of its own pose.
  WorldMap own(options_);
  ASSERT_EQ(own.AddSensor("sr", spec_), MapStatus::kOk);
  ASSERT_EQ(Add(&own, "sr", turned, cloud), MapStatus::kOk);
  ASSERT_EQ(own.Render("sr"), MapStatus::kOk);
  ASSERT_GT(own.tree().getNumLeafNodes(), 100u);
  // Every voxel the period maps lies within a voxel of one the cloud's own pose maps (binned as
  // if taken at the period's pose, the old way, 1.2 % lie farther: 0.988); the beams re-binned
  // from the turned frame lose a few the other way round (0.993).
  EXPECT_GE(OccupiedNear(via_period.tree(), own.tree()), 0.998);
  EXPECT_GE(OccupiedNear(own.tree(), via_period.tree()), 0.98);
}

// WouldSeal says beforehand what Integrate (may_seal) does with the open period, and a cloud
// that seals it leaves its grid as it was (fusiond's integrator relies on both while the
// renderer reads that grid).
TEST_F(WorldMapTest, WouldSealTellsWhetherACloudLeavesTheOpenPeriodAlone) {
  SensorPeriods periods(spec_, SensorGridOptions(options_), options_.pose_tolerance_m,
                        options_.pose_tolerance_rad, kRes);
  const auto frame = Frame();
  EXPECT_FALSE(periods.WouldSeal(pose_)) << "an empty period takes any cloud";
  std::unique_ptr<Period> sealed;
  PeriodIntegration result;
  ASSERT_EQ(periods.Integrate(pose_, frame.xyz.data(), frame.size(), frame.beyond_range, true,
                              &result, &sealed),
            MapStatus::kOk);
  Eigen::Isometry3d nudged = pose_;
  nudged.translation().y() += 0.005;
  Eigen::Isometry3d moved = pose_;
  moved.translation().x() += 0.05;
  Eigen::Isometry3d turned = pose_;
  turned.linear() = turned.linear() * Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitY()).matrix();
  Eigen::Isometry3d broken = moved;
  broken.translation().z() = std::nan("");
  Eigen::Isometry3d outside = pose_;
  outside.translation().x() = 1e6;
  EXPECT_FALSE(periods.WouldSeal(pose_));
  EXPECT_FALSE(periods.WouldSeal(nudged)) << "within the tolerance";
  EXPECT_TRUE(periods.WouldSeal(moved));
  EXPECT_TRUE(periods.WouldSeal(turned));
  EXPECT_FALSE(periods.WouldSeal(broken)) << "refused, not sealed";
  EXPECT_FALSE(periods.WouldSeal(outside)) << "refused, not sealed";

  const Period* open = &periods.open();
  const BeamGrid* grid = open->grid.get();
  const std::vector<double> before = grid->FirstHitProbabilities(0);
  const auto other = simulator_.Capture(moved);
  ASSERT_EQ(periods.Integrate(moved, other.xyz.data(), other.size(), other.beyond_range, true,
                              &result, &sealed),
            MapStatus::kOk);
  ASSERT_NE(sealed, nullptr);
  EXPECT_EQ(sealed.get(), open) << "the same period object, handed over whole";
  EXPECT_EQ(sealed->grid.get(), grid);
  EXPECT_EQ(sealed->frames, 1u);
  EXPECT_EQ(grid->FirstHitProbabilities(0), before);
  EXPECT_NE(&periods.open(), open);
  EXPECT_EQ(periods.open().frames, 1u);
}

// A frame turned and moved within the tolerance sees past its period's first view: its
// readings there land in the grid's margin (SensorPeriods), not rejected; the sensor's own grid
// would have lost them.
TEST_F(WorldMapTest, AFrameWithinTheToleranceKeepsItsReadingsPastThePeriodsView) {
  SensorPeriods periods(spec_, SensorGridOptions(options_), options_.pose_tolerance_m,
                        options_.pose_tolerance_rad, kRes);
  const BeamMargin& margin = periods.beam_margin();
  ASSERT_GT(margin.cols, 0);
  ASSERT_GT(margin.rows, 0);
  std::unique_ptr<Period> sealed;
  PeriodIntegration result;
  const auto first = Frame();
  ASSERT_EQ(periods.Integrate(pose_, first.xyz.data(), first.size(), first.beyond_range, true,
                              &result, &sealed),
            MapStatus::kOk);
  EXPECT_EQ(result.stats.rejected_outside_fov, 0u);
  Eigen::Isometry3d turned = pose_;
  turned.linear() = turned.linear() *
                    Eigen::AngleAxisd(0.6 * options_.pose_tolerance_rad, Eigen::Vector3d::UnitY())
                        .matrix() *
                    Eigen::AngleAxisd(0.6 * options_.pose_tolerance_rad, Eigen::Vector3d::UnitX())
                        .matrix();
  turned.translation() += pose_.linear() * Eigen::Vector3d(0.6, 0.6, 0.0) *
                          options_.pose_tolerance_m;
  ASSERT_FALSE(periods.WouldSeal(turned));
  const auto second = simulator_.Capture(turned);
  ASSERT_EQ(periods.Integrate(turned, second.xyz.data(), second.size(), second.beyond_range,
                              true, &result, &sealed),
            MapStatus::kOk);
  ASSERT_EQ(sealed, nullptr);
  EXPECT_EQ(result.stats.rejected_outside_fov, 0u);
  // The same points in the period's frame, binned into the sensor's own beams.
  const Eigen::Isometry3d T_period_cloud = pose_.inverse() * turned;
  std::vector<float> moved;
  for (std::size_t k = 0; k < second.size(); ++k) {
    const Eigen::Vector3d p(second.xyz[3 * k], second.xyz[3 * k + 1], second.xyz[3 * k + 2]);
    const Eigen::Vector3d q = p.allFinite() && !p.isZero() ? T_period_cloud * p : p;
    for (int a = 0; a < 3; ++a) moved.push_back(static_cast<float>(q[a]));
  }
  BeamGrid own(spec_, SensorGridOptions(options_));
  EXPECT_GT(own.Integrate(moved.data(), second.size(), second.beyond_range).rejected_outside_fov,
            10u)
      << "the test's turn must take readings past the first view";
  // Those readings touched beams of the margin.
  const BeamGrid& grid = *periods.open().grid;
  const int cols = grid.tessellation().cols();
  std::size_t margin_touched = 0;
  for (std::size_t b = 0; b < grid.tessellation().beam_count(); ++b) {
    const int c = static_cast<int>(b % static_cast<std::size_t>(cols));
    const int r = static_cast<int>(b / static_cast<std::size_t>(cols));
    const bool own_beam = c >= margin.cols && c < margin.cols + spec_.cols &&
                          r >= margin.rows && r < margin.rows + spec_.rows;
    if (!own_beam && grid.Touched(b)) ++margin_touched;
  }
  EXPECT_GT(margin_touched, 0u);
}

TEST_F(WorldMapTest, CommitOnRequestKeepsTheMapAndRestartsTheGrid) {
  WorldMap map(options_);
  ASSERT_EQ(map.AddSensor("sr", spec_), MapStatus::kOk);
  for (int i = 0; i < 3; ++i) ASSERT_EQ(Add(&map, "sr", pose_, Frame()), MapStatus::kOk);
  ASSERT_EQ(map.Render("sr"), MapStatus::kOk);
  const octomap::OcTree rendered(map.tree());
  ASSERT_EQ(map.Commit("sr"), MapStatus::kOk);
  ExpectSameLeaves(rendered,
                   map.tree());  // committing changes nothing queries see
  const BeamGrid* grid = map.beam_grid("sr");
  ASSERT_NE(grid, nullptr);
  for (std::size_t b = 0; b < grid->tessellation().beam_count(); ++b)
    ASSERT_FALSE(grid->Touched(b));
  // An empty re-render after the commit does not remove the committed evidence.
  ASSERT_EQ(map.Render("sr"), MapStatus::kOk);
  ExpectSameLeaves(rendered, map.tree());
}

TEST_F(WorldMapTest, PublicationsNameTheRegionsTheyChanged) {
  WorldMap map(options_);
  ASSERT_EQ(map.AddSensor("sr", spec_), MapStatus::kOk);
  ASSERT_EQ(Add(&map, "sr", pose_, Frame()), MapStatus::kOk);
  ASSERT_EQ(map.Render("sr"), MapStatus::kOk);
  const Publication first = map.Publish();
  EXPECT_EQ(first.changes.version, 1u);
  // The first version changed everything the map holds.
  std::size_t covered = 0;
  for (auto it = first.tree->begin_leafs(); it != first.tree->end_leafs(); ++it) ++covered;
  EXPECT_GT(covered, 0u);
  EXPECT_GE(first.changes.regions.size(), covered / 8);
  const octomap::OcTree before(*first.tree);
  ASSERT_EQ(Add(&map, "sr", pose_, Frame()), MapStatus::kOk);
  ASSERT_EQ(map.Render("sr"), MapStatus::kOk);
  const Publication second = map.Publish();
  EXPECT_EQ(second.changes.version, 2u);
  EXPECT_FALSE(second.changes.reset);
  ASSERT_FALSE(second.changes.regions.empty());
  // Every voxel whose value changed lies in a reported region; the first tree was not touched.
  const auto reported = [&](const octomap::OcTreeKey& key) {
    const std::uint64_t code = MortonOf(key);
    for (const MapRegion& r : second.changes.regions) {
      if (code >= r.code && code < r.code + MortonSpan(r.depth)) return true;
    }
    return false;
  };
  std::size_t changed_voxels = 0;
  for (auto it = second.tree->begin_leafs(); it != second.tree->end_leafs(); ++it) {
    if (it.getDepth() < 13) continue;  // large free blocks: checked through their neighbours
    const int side = 1 << (16 - it.getDepth());
    const octomap::OcTreeKey first_key = KeyOfMorton(MortonAtDepth(MortonOf(it.getKey()), it.getDepth()));
    for (int x = 0; x < side; ++x)
      for (int y = 0; y < side; ++y)
        for (int z = 0; z < side; ++z) {
          const octomap::OcTreeKey k(first_key[0] + x, first_key[1] + y, first_key[2] + z);
          const octomap::OcTreeNode* old = before.search(k);
          if (old != nullptr && old->getLogOdds() == it->getLogOdds()) continue;
          ++changed_voxels;
          ASSERT_TRUE(reported(k));
        }
  }
  EXPECT_GT(changed_voxels, 0u);
  ExpectSameLeaves(before, *first.tree);
}

TEST_F(WorldMapTest, TwoSensorsFuseWithEq16) {
  WorldMap map(options_);
  ASSERT_EQ(map.AddSensor("a", spec_), MapStatus::kOk);
  ASSERT_EQ(map.AddSensor("b", spec_), MapStatus::kOk);
  // Sensor b stands 0.3 m closer and 0.2 m to the left; both see the board.
  Eigen::Isometry3d pose_b = pose_;
  pose_b.translation() = Eigen::Vector3d(0.3, 0.2, 0.0);
  for (int i = 0; i < 3; ++i) {
    ASSERT_EQ(Add(&map, "a", pose_, Frame()), MapStatus::kOk);
    ASSERT_EQ(Add(&map, "b", pose_b, simulator_.Capture(pose_b)), MapStatus::kOk);
  }
  ASSERT_EQ(map.Render("a"), MapStatus::kOk);
  ASSERT_EQ(map.Render("b"), MapStatus::kOk);
  // Each sensor's opinion: its beam grid rendered alone. Every shared voxel
  // must hold Eq. 16 of the two.
  const RenderedGrid la = Opinion(map, "a", pose_);
  const RenderedGrid lb = Opinion(map, "b", pose_b);
  std::size_t shared = 0;
  std::size_t disagreeing = 0;
  for (const MapNode& node_a : la.nodes()) {
    const octomap::OcTreeKey key = KeyOfMorton(node_a.code);
    const float l_a = node_a.log_odds;
    const auto l_b = lb.LogOddsAt(key);
    if (!l_b) continue;
    ++shared;
    const double p_a = ProbabilityFromLogOdds(l_a);
    const double p_b = ProbabilityFromLogOdds(*l_b);
    const double expected = std::clamp(FuseIndependentOpinionPool(p_a, p_b), 0.001, 0.999);
    const octomap::OcTreeNode* node = map.tree().search(key);
    ASSERT_NE(node, nullptr);
    EXPECT_NEAR(node->getOccupancy(), expected, 1e-4);
    if ((p_a > 0.6 && p_b < 0.4) || (p_a < 0.4 && p_b > 0.6)) ++disagreeing;
  }
  EXPECT_GT(shared, 1000u);
  EXPECT_GT(disagreeing,
            0u);  // one sees occupied, the other free: Eq. 16 decides
}

TEST_F(WorldMapTest, MaxAndDeMorganRules) {
  for (FusionRule rule : {FusionRule::kMax, FusionRule::kDeMorgan}) {
    options_.rule = rule;
    WorldMap map(options_);
    ASSERT_EQ(map.AddSensor("a", spec_), MapStatus::kOk);
    ASSERT_EQ(map.AddSensor("b", spec_), MapStatus::kOk);
    Eigen::Isometry3d pose_b = pose_;
    pose_b.translation() = Eigen::Vector3d(0.0, 0.05, 0.0);
    ASSERT_EQ(Add(&map, "a", pose_, Frame()), MapStatus::kOk);
    ASSERT_EQ(Add(&map, "b", pose_b, simulator_.Capture(pose_b)), MapStatus::kOk);
    ASSERT_EQ(map.Render("a"), MapStatus::kOk);
    ASSERT_EQ(map.Render("b"), MapStatus::kOk);
    const RenderedGrid la = Opinion(map, "a", pose_);
    const RenderedGrid lb = Opinion(map, "b", pose_b);
    std::size_t checked = 0;
    for (const MapNode& node_a : la.nodes()) {
      const octomap::OcTreeKey key = KeyOfMorton(node_a.code);
      const auto l_b = lb.LogOddsAt(key);
      if (!l_b || checked > 2000) continue;
      ++checked;
      const double expected = std::clamp(
          Fuse(rule, ProbabilityFromLogOdds(node_a.log_odds), ProbabilityFromLogOdds(*l_b)),
          0.001, 0.999);
      EXPECT_NEAR(map.tree().search(key)->getOccupancy(), expected, 1e-4);
    }
    EXPECT_GT(checked, 100u);
  }
}

}  // namespace
}  // namespace fusion
