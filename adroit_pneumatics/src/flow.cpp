#include "adroit_pneumatics/flow.h"

#include <algorithm>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>

namespace adroit::pneumatics {

using namespace constants;

double flowAlpha() {
  return kDischarge * std::sqrt(2.0 * kMolarMass / (kCompressibility * kGasConstant * kTemperature) *
                                kKappa / (kKappa - 1.0));
}

double flowBeta() {
  return kDischarge * std::sqrt(kKappa * kMolarMass / (kCompressibility * kGasConstant * kTemperature) *
                                std::pow(2.0 / (kKappa + 1.0), (kKappa + 1.0) / (kKappa - 1.0)));
}

double chokeRatio() { return std::pow((kKappa + 1.0) / 2.0, kKappa / (kKappa - 1.0)); }

double flowZ(double p_up, double p_down) {
  if (p_up / p_down > chokeRatio()) return flowBeta() * p_up;
  const double r = p_down / p_up;
  const double h = std::pow(r, 2.0 / kKappa) - std::pow(r, (kKappa + 1.0) / kKappa);
  return flowAlpha() * p_up * std::sqrt(std::max(0.0, h));
}

double flowPhi(double p_up, double p_down) {
  return p_up >= p_down ? flowZ(p_up, p_down) : -flowZ(p_down, p_up);
}

FlowTable::FlowTable() {
  alpha_ = flowAlpha();
  beta_ = flowBeta();
  r_choke_ = 1.0 / chokeRatio();
  inv_step_ = kSegments / (1.0 - r_choke_);
  for (int i = 0; i <= kSegments + 1; ++i) {
    const double r = std::min(1.0, r_choke_ + i / inv_step_);
    h_[i] = std::max(0.0, std::pow(r, 2.0 / kKappa) - std::pow(r, (kKappa + 1.0) / kKappa));
    g_[i] = alpha_ * std::sqrt(h_[i]);
  }
  for (int i = 0; i <= kSegments; ++i) {
    const double mid = std::max(0.5 * (h_[i] + h_[i + 1]), 1e-12);
    dg_[i] = alpha_ * (h_[i + 1] - h_[i]) * inv_step_ / (2.0 * std::sqrt(mid));
  }
}

const FlowTable& flowTable() {
  static const FlowTable table;
  return table;
}

GompertzTable::GompertzTable(double b) : b_(b) {
  if (!(b > 0) || !std::isfinite(b)) throw std::invalid_argument("GompertzTable: b must be finite and > 0");
  // H(x_lo) = exp(-40) and 1 - H(x_hi) = b exp(-x_hi) = 1e-7.
  x_lo_ = std::log(b / 40.0);
  x_hi_ = std::log(b / 1e-7);
  inv_step_ = kSegments / (x_hi_ - x_lo_);
  for (int i = 0; i <= kSegments + 1; ++i) h_[i] = std::exp(-b * std::exp(-(x_lo_ + i / inv_step_)));
}

const GompertzTable& gompertzTable(double b) {
  static std::mutex mutex;
  static std::map<double, std::unique_ptr<GompertzTable>> tables;
  std::lock_guard<std::mutex> lock(mutex);
  auto& slot = tables[b];
  if (!slot) slot = std::make_unique<GompertzTable>(b);
  return *slot;
}

ValveParams valveParams(int which) {
  // Table 4.4 (offset, a, b, c, d).
  if (which == 1)
    return {{2.9274e-08, 5.501e-07, 3.539, 1.564, 0.12}, {2.6076e-08, 6.079e-07, 3.149, -1.365, -0.1}};
  if (which == 2)
    return {{2.627e-08, 8.731e-07, 4.029, 0.929, -0.1505}, {2.964e-08, 8.659e-07, 3.942, -0.9816, 0.1584}};
  throw std::invalid_argument("valveParams: unknown valve " + std::to_string(which) + " (table 4.4 has 1 and 2)");
}

}  // namespace adroit::pneumatics
