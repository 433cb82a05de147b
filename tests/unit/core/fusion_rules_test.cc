#include "fusion/core/fusion_rules.h"

#include <gtest/gtest.h>

#include <cmath>

namespace fusion {
namespace {

const double kValues[] = {0.01, 0.1, 0.3, 0.5, 0.62, 0.9, 0.999};

TEST(FusionRules, NamesRoundTrip) {
  EXPECT_EQ(FusionRuleFromName("bayes"), FusionRule::kIndependentOpinionPool);
  EXPECT_EQ(FusionRuleFromName("independent_opinion_pool"), FusionRule::kIndependentOpinionPool);
  EXPECT_EQ(FusionRuleFromName("max"), FusionRule::kMax);
  EXPECT_EQ(FusionRuleFromName("demorgan"), FusionRule::kDeMorgan);
  EXPECT_FALSE(FusionRuleFromName("average").has_value());
  EXPECT_FALSE(FusionRuleFromName("").has_value());
  for (const auto& name : FusionRuleNames()) {
    const auto rule = FusionRuleFromName(name);
    ASSERT_TRUE(rule.has_value()) << name;
    EXPECT_EQ(FusionRuleFromName(FusionRuleName(*rule)), rule);
  }
}

TEST(FusionRules, Eq16MatchesClosedForm) {
  // p = p1 p2 / (p1 p2 + (1 - p1)(1 - p2))
  EXPECT_NEAR(FuseIndependentOpinionPool(0.9, 0.2), 0.18 / (0.18 + 0.08), 1e-15);
  EXPECT_NEAR(FuseIndependentOpinionPool(0.7, 0.7), 0.49 / (0.49 + 0.09), 1e-15);
  // Log-odds add.
  for (double a : kValues) {
    for (double b : kValues) {
      EXPECT_NEAR(LogOdds(FuseIndependentOpinionPool(a, b)), LogOdds(a) + LogOdds(b), 1e-9);
    }
  }
}

TEST(FusionRules, Eq16Commutative) {
  for (double a : kValues) {
    for (double b : kValues) {
      EXPECT_DOUBLE_EQ(FuseIndependentOpinionPool(a, b), FuseIndependentOpinionPool(b, a));
      EXPECT_DOUBLE_EQ(FuseMax(a, b), FuseMax(b, a));
      EXPECT_DOUBLE_EQ(FuseDeMorgan(a, b), FuseDeMorgan(b, a));
    }
  }
}

TEST(FusionRules, Eq16Associative) {
  for (double a : kValues) {
    for (double b : kValues) {
      for (double c : kValues) {
        for (FusionRule rule :
             {FusionRule::kIndependentOpinionPool, FusionRule::kMax, FusionRule::kDeMorgan}) {
          EXPECT_NEAR(Fuse(rule, Fuse(rule, a, b), c), Fuse(rule, a, Fuse(rule, b, c)), 1e-12)
              << FusionRuleName(rule) << " " << a << " " << b << " " << c;
        }
      }
    }
  }
}

TEST(FusionRules, HalfIsNeutralForEq16Only) {
  for (double a : kValues) {
    EXPECT_NEAR(FuseIndependentOpinionPool(a, 0.5), a, 1e-15);
    EXPECT_NEAR(FuseIndependentOpinionPool(0.5, a), a, 1e-15);
  }
  // Max and De Morgan are not neutral at 0.5: unknown voxels must be left out,
  // not fused.
  EXPECT_DOUBLE_EQ(FuseMax(0.2, 0.5), 0.5);
  EXPECT_DOUBLE_EQ(FuseDeMorgan(0.5, 0.5), 0.75);
  EXPECT_DOUBLE_EQ(FuseDeMorgan(0.3, 0.0), 0.3);
}

TEST(FusionRules, DisagreementEndsWhereEq16PutsIt) {
  // One sensor sees the voxel occupied, the other free: the pooled opinion lies
  // between, on the side of the more confident sensor.
  const double occupied = 0.9;
  const double free = 0.3;
  const double fused = FuseIndependentOpinionPool(occupied, free);
  EXPECT_NEAR(fused, 0.27 / (0.27 + 0.07), 1e-15);
  EXPECT_GT(fused, 0.5);
  EXPECT_LT(fused, occupied);
  EXPECT_NEAR(FuseIndependentOpinionPool(0.8, 0.2), 0.5,
              1e-15);  // equal and opposite
  EXPECT_DOUBLE_EQ(FuseMax(occupied, free), 0.9);
  EXPECT_NEAR(FuseDeMorgan(occupied, free), 1.0 - 0.1 * 0.7, 1e-15);
}

TEST(FusionRules, ExtremesAreSafe) {
  EXPECT_DOUBLE_EQ(FuseIndependentOpinionPool(0.0, 1.0), 0.5);
  EXPECT_DOUBLE_EQ(FuseIndependentOpinionPool(1.0, 0.7), 1.0);
  EXPECT_DOUBLE_EQ(FuseIndependentOpinionPool(0.0, 0.7), 0.0);
  EXPECT_DOUBLE_EQ(FuseAll(FusionRule::kIndependentOpinionPool, {}), 0.5);
  EXPECT_NEAR(FuseAll(FusionRule::kIndependentOpinionPool, {0.7, 0.6, 0.2}),
              FuseIndependentOpinionPool(FuseIndependentOpinionPool(0.7, 0.6), 0.2), 1e-15);
}

}  // namespace
}  // namespace fusion
