// fusion_fig2: prints the paper's Fig. 2 (classic beam model, 20 updates at r = 0.5) as a table.
#include <cstdio>

#include "fusion/core/fig2.h"

int main() {
  const std::vector<fusion::Fig2Row> rows = fusion::ReproduceFig2(20);
  std::printf(
      "# Fig. 2: 21 cells of width 1/21 over [0, 1], p(m) = 0.5 at start, classic beam "
      "model (sigma_hit = 0.1 m), reading r = 0.5 (cell 11) applied 20 times.\n");
  std::printf("%6s %9s %9s %9s %9s %9s %9s %9s\n", "update", "p(B_11)", "p(m_11)", "p(m_5)",
              "p(m_9)", "p(m_10)", "p(m_12)", "p(B_22)");
  for (const fusion::Fig2Row& r : rows) {
    std::printf("%6d %9.5f %9.5f %9.5f %9.5f %9.5f %9.5f %9.2e\n", r.update, r.p_b[10], r.p_m[10],
                r.p_m[4], r.p_m[8], r.p_m[9], r.p_m[11], r.p_b[21]);
  }
  std::printf("\n# p(B_i) after update 20, i = 1..22:\n");
  const fusion::Fig2Row& last = rows.back();
  for (std::size_t i = 0; i < last.p_b.size(); ++i) {
    std::printf("%s%.4f", i == 0 ? "" : " ", last.p_b[i]);
  }
  std::printf("\n# p(m_i) after update 20, i = 1..21:\n");
  for (std::size_t i = 0; i < last.p_m.size(); ++i) {
    std::printf("%s%.4f", i == 0 ? "" : " ", last.p_m[i]);
  }
  std::printf("\n");
  return 0;
}
