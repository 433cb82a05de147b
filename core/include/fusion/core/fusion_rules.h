// Per-voxel fusion of occupancy opinions from several sensors (paper Eq. 16)
// and the non-Bayesian alternatives the paper mentions (max, De Morgan).
//
// Every function takes and returns occupancy probabilities in [0, 1]; log-odds
// helpers use the natural logarithm, as OctoMap does.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

namespace fusion {

enum class FusionRule {
  // Eq. 16: p = p1 p2 / (p1 p2 + (1 - p1)(1 - p2)), i.e. log-odds add. 0.5 is
  // neutral.
  kIndependentOpinionPool,
  // p = max(p1, p2): conservative for obstacles, never lowers occupancy.
  kMax,
  // p = 1 - (1 - p1)(1 - p2): "occupied if any sensor says occupied". 0 is
  // neutral, so an
  // unknown (0.5) voxel must be left out of the fusion rather than fused as
  // 0.5.
  kDeMorgan,
};

// "bayes" or "independent_opinion_pool", "max", "demorgan"; std::nullopt for
// anything else.
[[nodiscard]] std::optional<FusionRule> FusionRuleFromName(const std::string& name);
// Canonical name: "independent_opinion_pool", "max" or "demorgan".
[[nodiscard]] std::string FusionRuleName(FusionRule rule);
[[nodiscard]] std::vector<std::string> FusionRuleNames();

[[nodiscard]] double LogOdds(double probability);
[[nodiscard]] double ProbabilityFromLogOdds(double log_odds);

// Eq. 16 on two probabilities. Exact 0/1 inputs are handled (0 with 1 gives
// 0.5).
[[nodiscard]] double FuseIndependentOpinionPool(double p1, double p2);
[[nodiscard]] double FuseMax(double p1, double p2);
[[nodiscard]] double FuseDeMorgan(double p1, double p2);
[[nodiscard]] double Fuse(FusionRule rule, double p1, double p2);
// Folds a list of opinions with the rule; an empty list gives 0.5 (unknown).
[[nodiscard]] double FuseAll(FusionRule rule, const std::vector<double>& probabilities);

// The fusion of the map: one rule over log-odds opinions, the result clamped (as OctoMap's
// clamping) so that the map stays updatable. Every fused value of the system (committed history,
// the map queries read, a snapshot loaded at start) comes from Fuse.
struct FusionPolicy {
  static constexpr double kDefaultClampingMin = 0.001;
  static constexpr double kDefaultClampingMax = 0.999;

  FusionRule rule = FusionRule::kIndependentOpinionPool;
  float clamp_min_log_odds = static_cast<float>(-6.906754778648554);  // logit(0.001)
  float clamp_max_log_odds = static_cast<float>(6.906754778648554);   // logit(0.999)

  // From clamping probabilities in (0, 1), min < max.
  [[nodiscard]] static FusionPolicy Make(FusionRule rule, double clamping_min_probability,
                                         double clamping_max_probability);
  // The rule over n >= 1 log-odds opinions, clamped.
  [[nodiscard]] float Fuse(const float* log_odds, std::size_t n) const;
};

}  // namespace fusion
