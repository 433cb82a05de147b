#include "calibrate_plot.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>

#include "map_render.h"

namespace fusion::clients {
namespace {

constexpr int kWidth = 1100, kHeight = 700;
constexpr int kLeft = 110, kRight = 30, kTop = 50, kBottom = 80;
constexpr int kScale = 2;  // font pixels per glyph pixel

struct Rgb {
  std::uint8_t r, g, b;
};
constexpr Rgb kWhite{255, 255, 255}, kBlack{0, 0, 0}, kGrid{225, 225, 225};
constexpr Rgb kInlier{40, 90, 200}, kOutlier{220, 40, 30}, kBand{200, 235, 200};
constexpr Rgb kBandEdge{30, 140, 60}, kZero{150, 150, 150};

// 5 x 7 glyphs, '#' = ink. Upper case is drawn as lower case.
const std::map<char, const char*>& Font() {
  static const std::map<char, const char*> font = {
      {'0', " ### #   ##  ### # ###  ##   # ### "}, {'1', "  #   ##    #    #    #    #   ### "},
      {'2', " ### #   #    #   #   #   #   #####"}, {'3', "#####   #   #     #     ##   # ### "},
      {'4', "   #   ##  # # #  # #####   #    # "}, {'5', "######    ####     #    ##   # ### "},
      {'6', "  ##  #   #    #### #   ##   # ### "}, {'7', "#####    #   #   #   #    #    #   "},
      {'8', " ### #   ##   # ### #   ##   # ### "}, {'9', " ### #   ##   # ####    #   #  ##  "},
      {'.', "                          ##   ##  "}, {'-', "               #####               "},
      {'+', "       #    #  #####  #    #       "}, {'(', "   #   #   #    #    #     #     # "},
      {')', " #     #     #    #    #   #   #   "}, {':', "      ##   ##        ##   ##       "},
      {',', "                     ##    #   #   "}, {'=', "          #####     #####          "},
      {'%', "##   ##  #   #   #   #   #  ##   ##"}, {'/', "         #   #   #   #   #         "},
      {'_', "                              #####"}, {'a', "           ###     # #####   # ####"},
      {'b', "#    #    # ## ##  ##   ##   ##### "}, {'c', "           ### #    #    #   # ### "},
      {'d', "    #    # ## ##  ###   ##   # ####"}, {'e', "           ### #   #######     ### "},
      {'f', "  ##  #  # #   ###   #    #    #   "}, {'g', "      #####   ##   # ####    # ### "},
      {'h', "#    #    # ## ##  ##   ##   ##   #"}, {'i', "  #        ##    #    #    #   ### "},
      {'j', "   #        ##    #    # #  #  ##  "}, {'k', "#    #    #  # # #  ##   # #  #  # "},
      {'l', " ##    #    #    #    #    #   ### "}, {'m', "          ## # # # ## # ##   ##   #"},
      {'n', "          # ## ##  ##   ##   ##   #"}, {'o', "           ### #   ##   ##   # ### "},
      {'p', "          #### #   ##### #    #    "}, {'q', "           ## ##  ## ####    #    #"},
      {'r', "          # ## ##  ##    #    #    "}, {'s', "           #####     ###     ##### "},
      {'t', " #    #   ###   #    #    #  #  ## "}, {'u', "          #   ##   ##   ##  ## ## #"},
      {'v', "          #   ##   ##   # # #   #  "}, {'w', "          #   ##   ## # ## # # # # "},
      {'x', "          #   # # #   #   # # #   #"}, {'y', "          #   ##   # ####    # ### "},
      {'z', "          #####   #   #   #   #####"}};
  return font;
}

class Canvas {
 public:
  Canvas() {
    image_.width = kWidth;
    image_.height = kHeight;
    image_.rgb.assign(static_cast<std::size_t>(3 * kWidth * kHeight), 255);
  }
  void Set(int x, int y, Rgb c, double alpha = 1.0) {
    if (x < 0 || y < 0 || x >= kWidth || y >= kHeight) return;
    std::uint8_t* p = &image_.rgb[static_cast<std::size_t>(3 * (y * kWidth + x))];
    const auto mix = [alpha](std::uint8_t old, std::uint8_t ink) {
      return static_cast<std::uint8_t>(std::lround(old + alpha * (ink - old)));
    };
    p[0] = mix(p[0], c.r);
    p[1] = mix(p[1], c.g);
    p[2] = mix(p[2], c.b);
  }
  void Fill(int x0, int y0, int x1, int y1, Rgb c) {
    for (int y = std::min(y0, y1); y <= std::max(y0, y1); ++y)
      for (int x = std::min(x0, x1); x <= std::max(x0, x1); ++x) Set(x, y, c);
  }
  void Line(double x0, double y0, double x1, double y1, Rgb c, int thickness = 1) {
    const int steps = static_cast<int>(std::max(std::abs(x1 - x0), std::abs(y1 - y0))) + 1;
    for (int s = 0; s <= steps; ++s) {
      const double f = static_cast<double>(s) / steps;
      const int x = static_cast<int>(std::lround(x0 + f * (x1 - x0)));
      const int y = static_cast<int>(std::lround(y0 + f * (y1 - y0)));
      Fill(x - thickness / 2, y - thickness / 2, x + (thickness - 1) / 2, y + (thickness - 1) / 2,
           c);
    }
  }
  // Text with its top left corner at (x, y); vertical text runs upwards from (x, y).
  void Text(int x, int y, const std::string& text, Rgb c, bool vertical = false) {
    int pen = 0;
    for (char ch : text) {
      const char key = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
      const auto glyph = Font().find(key);
      if (glyph != Font().end()) {
        for (int row = 0; row < 7; ++row) {
          for (int col = 0; col < 5; ++col) {
            if (glyph->second[row * 5 + col] != '#') continue;
            const int gx = pen + col * kScale, gy = row * kScale;
            if (vertical) {
              Fill(x + gy, y - gx, x + gy + kScale - 1, y - gx - kScale + 1, c);
            } else {
              Fill(x + gx, y + gy, x + gx + kScale - 1, y + gy + kScale - 1, c);
            }
          }
        }
      }
      pen += 6 * kScale;
    }
  }
  static int TextWidth(const std::string& text) {
    return static_cast<int>(text.size()) * 6 * kScale;
  }
  const render::Image& image() const { return image_; }

 private:
  render::Image image_;
};

// A tick step of 1, 2 or 5 times a power of ten giving about `target` ticks over `span`.
double TickStep(double span, int target) {
  const double raw = span / target;
  const double power = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    if (m * power >= raw) return m * power;
  }
  return 10.0 * power;
}

std::string Format(double v, double step) {
  const int decimals = std::max(0, static_cast<int>(-std::floor(std::log10(step) + 1e-9)));
  char text[32];
  std::snprintf(text, sizeof text, "%.*f", decimals, std::abs(v) < 1e-12 ? 0.0 : v);
  return text;
}

}  // namespace

bool WriteCalibrationPlot(const std::string& path, const std::vector<RangeSample>& samples,
                          const Calibration& fit, const std::string& title, std::string* error) {
  const double t_lo = fit.bins.front().begin_m, t_hi = fit.bins.back().end_m;
  // The y range shows the band well (5 sigma either side of the bias curve, and zero);
  // readings beyond it are drawn at the edge.
  double y_lo = 0.0, y_hi = 0.0;
  for (int k = 0; k <= 200; ++k) {
    const double t = t_lo + (t_hi - t_lo) * k / 200.0;
    const double bias = fit.q_mu(t) - t, sigma = std::max(0.0, fit.q_sigma(t));
    y_lo = std::min(y_lo, bias - 5.0 * sigma);
    y_hi = std::max(y_hi, bias + 5.0 * sigma);
  }
  const double pad = 0.05 * (y_hi - y_lo) + 1e-6;
  y_lo -= pad;
  y_hi += pad;
  const double plot_w = kWidth - kLeft - kRight, plot_h = kHeight - kTop - kBottom;
  const auto px = [&](double t) { return kLeft + (t - t_lo) / (t_hi - t_lo) * plot_w; };
  const auto py = [&](double y) {
    return kTop + (1.0 - (std::clamp(y, y_lo, y_hi) - y_lo) / (y_hi - y_lo)) * plot_h;
  };
  Canvas canvas;
  // The band, filled, then grid lines.
  for (int x = kLeft; x < kWidth - kRight; ++x) {
    const double t = t_lo + (x - kLeft) / plot_w * (t_hi - t_lo);
    const double bias = fit.q_mu(t) - t, sigma = std::max(0.0, fit.q_sigma(t));
    canvas.Line(x, py(bias - 3 * sigma), x, py(bias + 3 * sigma), kBand);
  }
  const double x_step = TickStep(t_hi - t_lo, 8), y_step = TickStep(y_hi - y_lo, 8);
  for (double t = std::ceil(t_lo / x_step) * x_step; t <= t_hi; t += x_step) {
    canvas.Line(px(t), kTop, px(t), kTop + plot_h, kGrid);
    const std::string label = Format(t, x_step);
    canvas.Text(static_cast<int>(px(t)) - Canvas::TextWidth(label) / 2,
                kTop + static_cast<int>(plot_h) + 10, label, kBlack);
  }
  for (double y = std::ceil(y_lo / y_step) * y_step; y <= y_hi; y += y_step) {
    canvas.Line(kLeft, py(y), kLeft + plot_w, py(y), kGrid);
    const std::string label = Format(y, y_step);
    canvas.Text(kLeft - 8 - Canvas::TextWidth(label), static_cast<int>(py(y)) - 7, label, kBlack);
  }
  canvas.Line(kLeft, py(0.0), kLeft + plot_w, py(0.0), kZero);
  // Dots: at most ~80000, evenly strided; outliers on top, larger.
  const std::size_t stride = std::max<std::size_t>(1, samples.size() / 80000);
  for (int pass = 0; pass < 2; ++pass) {
    for (std::size_t i = 0; i < samples.size(); i += stride) {
      const double w = fit.inlier_responsibility[i];
      if (std::isnan(w) || (pass == 0) != (w >= 0.5)) continue;
      const double t = samples[i].true_range_m, y = samples[i].reading_m - t;
      const int x = static_cast<int>(std::lround(px(t))), v = static_cast<int>(std::lround(py(y)));
      if (pass == 0) {
        canvas.Set(x, v, kInlier, 0.35);
      } else {
        for (int d = 0; d < 4; ++d) canvas.Set(x + d % 2, v + d / 2, kOutlier, 0.8);
      }
    }
  }
  // Fitted mean bias and the +-3 sigma band's edges.
  for (int x = kLeft; x + 1 < kWidth - kRight; ++x) {
    const auto at = [&](int column, double k) {
      const double t = t_lo + (column - kLeft) / plot_w * (t_hi - t_lo);
      return py(fit.q_mu(t) - t + k * std::max(0.0, fit.q_sigma(t)));
    };
    canvas.Line(x, at(x, 3), x + 1, at(x + 1, 3), kBandEdge);
    canvas.Line(x, at(x, -3), x + 1, at(x + 1, -3), kBandEdge);
    canvas.Line(x, at(x, 0), x + 1, at(x + 1, 0), kBlack, 3);
  }
  // Frame, labels, legend.
  canvas.Line(kLeft, kTop, kLeft, kTop + plot_h, kBlack, 2);
  canvas.Line(kLeft, kTop + plot_h, kLeft + plot_w, kTop + plot_h, kBlack, 2);
  canvas.Line(kLeft, kTop, kLeft + plot_w, kTop, kBlack);
  canvas.Line(kLeft + plot_w, kTop, kLeft + plot_w, kTop + plot_h, kBlack);
  canvas.Text(kLeft, 15, title, kBlack);
  const std::string x_label = "true range t (m)";
  canvas.Text(kLeft + static_cast<int>(plot_w) / 2 - Canvas::TextWidth(x_label) / 2, kHeight - 35,
              x_label, kBlack);
  const std::string y_label = "reading - true range (m)";
  canvas.Text(12, kTop + static_cast<int>(plot_h) / 2 + Canvas::TextWidth(y_label) / 2, y_label,
              kBlack, true);
  int legend_y = kTop + 12;
  const int legend_x = kLeft + 20;
  const auto entry = [&](Rgb c, const std::string& text, bool line) {
    if (line) {
      canvas.Line(legend_x, legend_y + 7, legend_x + 24, legend_y + 7, c, 3);
    } else {
      canvas.Fill(legend_x + 8, legend_y + 3, legend_x + 15, legend_y + 10, c);
    }
    canvas.Text(legend_x + 34, legend_y, text, kBlack);
    legend_y += 22;
  };
  entry(kInlier, "inliers", false);
  entry(kOutlier, "outliers", false);
  entry(kBlack, "fitted bias q_mu(t) - t", true);
  entry(kBandEdge, "+-3 sigma, q_sigma(t)", true);
  return render::WritePng(path, canvas.image(), error);
}

}  // namespace fusion::clients
