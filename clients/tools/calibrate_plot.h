// fusion-calibrate's --plot: residual (reading - true range) against true range, inliers and
// outliers in two colours, the fitted mean bias and its +-3 sigma band, labelled axes (a tiny
// bitmap font: no font library needed), written as an RGB PNG.
#pragma once

#include <string>
#include <vector>

#include "fusion/core/calibration.h"

namespace fusion::clients {

// `fit` must be a successful CalibrateForwardModel(samples, ...) (its responsibilities index
// `samples`). False with *error when the file cannot be written.
bool WriteCalibrationPlot(const std::string& path, const std::vector<RangeSample>& samples,
                          const Calibration& fit, const std::string& title, std::string* error);

}  // namespace fusion::clients
