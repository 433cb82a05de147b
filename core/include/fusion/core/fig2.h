// Reproduction of the paper's Fig. 2: the classic beam model applied 20 times (Eq. 11) to the
// same reading r = 0.5 on a beam of 21 cells of width 1/21 over [0, 1] (cell 11's centre is at
// 0.5), starting from p(m_i) = 0.5.
#pragma once

#include <cstddef>
#include <vector>

#include "fusion/core/sensor.h"

namespace fusion {

struct Fig2Row {
  int update = 0;           // 0 = before the first update
  std::vector<double> p_b;  // p(B_1..B_22)
  std::vector<double> p_m;  // p(m_1..m_21)
};

// The sensor used: classic model, r_min = 0, r_max = 1, sigma_hit = 0.1 (so that
// p(r | B_11) peaks near 0.15 as in Fig. 2(a)), other weights the ClassicBeamParams defaults.
[[nodiscard]] SensorSpec Fig2Sensor();
inline constexpr std::size_t kFig2Cells = 21;
inline constexpr double kFig2Reading = 0.5;

// Rows 0..updates, computed with the dense reference beam.
[[nodiscard]] std::vector<Fig2Row> ReproduceFig2(int updates = 20);

}  // namespace fusion
