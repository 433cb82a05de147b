#include "fusion/core/fusion_rules.h"

#include <algorithm>
#include <cmath>

namespace fusion {

std::optional<FusionRule> FusionRuleFromName(const std::string& name) {
  if (name == "bayes" || name == "independent_opinion_pool") {
    return FusionRule::kIndependentOpinionPool;
  }
  if (name == "max") return FusionRule::kMax;
  if (name == "demorgan" || name == "de_morgan") return FusionRule::kDeMorgan;
  return std::nullopt;
}

std::string FusionRuleName(FusionRule rule) {
  switch (rule) {
    case FusionRule::kIndependentOpinionPool:
      return "independent_opinion_pool";
    case FusionRule::kMax:
      return "max";
    case FusionRule::kDeMorgan:
      return "demorgan";
  }
  return "independent_opinion_pool";
}

std::vector<std::string> FusionRuleNames() {
  return {"bayes", "independent_opinion_pool", "max", "demorgan"};
}

double LogOdds(double probability) { return std::log(probability / (1.0 - probability)); }

double ProbabilityFromLogOdds(double log_odds) { return 1.0 / (1.0 + std::exp(-log_odds)); }

double FuseIndependentOpinionPool(double p1, double p2) {
  const double occupied = p1 * p2;
  const double free = (1.0 - p1) * (1.0 - p2);
  const double total = occupied + free;
  if (total <= 0.0) return 0.5;  // certain disagreement: no opinion survives
  return occupied / total;
}

double FuseMax(double p1, double p2) { return std::max(p1, p2); }

double FuseDeMorgan(double p1, double p2) { return 1.0 - (1.0 - p1) * (1.0 - p2); }

double Fuse(FusionRule rule, double p1, double p2) {
  switch (rule) {
    case FusionRule::kIndependentOpinionPool:
      return FuseIndependentOpinionPool(p1, p2);
    case FusionRule::kMax:
      return FuseMax(p1, p2);
    case FusionRule::kDeMorgan:
      return FuseDeMorgan(p1, p2);
  }
  return FuseIndependentOpinionPool(p1, p2);
}

double FuseAll(FusionRule rule, const std::vector<double>& probabilities) {
  if (probabilities.empty()) return 0.5;
  double fused = probabilities.front();
  for (std::size_t i = 1; i < probabilities.size(); ++i) {
    fused = Fuse(rule, fused, probabilities[i]);
  }
  return fused;
}

FusionPolicy FusionPolicy::Make(FusionRule rule, double clamping_min_probability,
                                double clamping_max_probability) {
  FusionPolicy policy;
  policy.rule = rule;
  policy.clamp_min_log_odds = static_cast<float>(LogOdds(clamping_min_probability));
  policy.clamp_max_log_odds = static_cast<float>(LogOdds(clamping_max_probability));
  return policy;
}

float FusionPolicy::Fuse(const float* log_odds, std::size_t n) const {
  double fused = log_odds[0];
  switch (rule) {
    case FusionRule::kIndependentOpinionPool:  // Eq. 16: log-odds add
      for (std::size_t i = 1; i < n; ++i) fused += log_odds[i];
      break;
    case FusionRule::kMax:
      for (std::size_t i = 1; i < n; ++i) fused = std::max<double>(fused, log_odds[i]);
      break;
    case FusionRule::kDeMorgan: {
      double free = 1.0;
      for (std::size_t i = 0; i < n; ++i) free *= 1.0 - ProbabilityFromLogOdds(log_odds[i]);
      fused = LogOdds(std::clamp(1.0 - free, 1e-12, 1.0 - 1e-12));
      break;
    }
  }
  return std::clamp(static_cast<float>(fused), clamp_min_log_odds, clamp_max_log_odds);
}

}  // namespace fusion
