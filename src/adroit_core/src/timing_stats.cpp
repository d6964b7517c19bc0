#include "adroit_core/timing_stats.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>

namespace adroit {

double percentile(std::vector<double> values, double p) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  p = std::clamp(p, 0.0, 100.0);
  // Nearest rank: the smallest value with at least p% of the samples at or below it.
  const auto rank = static_cast<std::size_t>(std::ceil(p / 100.0 * values.size()));
  return values[rank == 0 ? 0 : rank - 1];
}

Summary SampleStats::summary() const {
  Summary s;
  s.count = samples_.size();
  if (samples_.empty()) return s;
  std::vector<double> sorted = samples_;
  std::sort(sorted.begin(), sorted.end());
  s.min = sorted.front();
  s.max = sorted.back();
  s.mean = std::accumulate(sorted.begin(), sorted.end(), 0.0) / sorted.size();
  s.median = percentile(sorted, 50.0);
  s.p99 = percentile(sorted, 99.0);
  return s;
}

std::string resultLine(const std::string& scope, const std::string& name, double value, const std::string& unit,
                       const std::string& op, double target) {
  const bool pass = op == "<=" ? value <= target
                    : op == "<" ? value < target
                    : op == ">=" ? value >= target
                    : op == ">" ? value > target
                                : false;
  char buf[512];
  std::snprintf(buf, sizeof(buf), "RESULT %s/%s %.4g %s target %s %.4g %s", scope.c_str(), name.c_str(), value,
                unit.c_str(), op.c_str(), target, pass ? "PASS" : "FAIL");
  return buf;
}

std::string formatSummary(const Summary& s, double scale, const std::string& unit) {
  char buf[160];
  std::snprintf(buf, sizeof(buf), "min %.3g / median %.3g / p99 %.3g / max %.3g %s", s.min * scale,
                s.median * scale, s.p99 * scale, s.max * scale, unit.c_str());
  return buf;
}

}  // namespace adroit
