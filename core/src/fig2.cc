// Paper Fig. 2 reproduction (classic model, 20 updates at r = 0.5).
#include "fusion/core/fig2.h"

#include "fusion/core/beam_grid.h"

namespace fusion {

SensorSpec Fig2Sensor() {
  SensorSpec s;
  s.name = "fig2";
  s.model = ForwardModelKind::kClassicBeam;
  s.r_min_m = 0.0;
  s.r_max_m = 1.0;
  s.fov_h_rad = 0.01;
  s.fov_v_rad = 0.01;
  s.cols = 1;
  s.rows = 1;
  s.classic.sigma_hit_m = 0.1;
  return s;
}

std::vector<Fig2Row> ReproduceFig2(int updates) {
  BeamGridOptions options;
  options.cell_size_m = 1.0 / static_cast<double>(kFig2Cells);
  options.prior_cell_occupancy = 0.5;
  options.representation = BeamRepresentation::kDense;
  BeamGrid grid(Fig2Sensor(), options);
  std::vector<Fig2Row> rows;
  for (int u = 0; u <= updates; ++u) {
    if (u > 0) grid.Update(0, Reading{Reading::Kind::kRange, kFig2Reading});
    rows.push_back({u, grid.FirstHitProbabilities(0), grid.CellProbabilities(0)});
  }
  return rows;
}

}  // namespace fusion
