#include "adroit_driver/command_check.h"

#include <cmath>
#include <cstdio>
#include "adroit_core/number_text.h"

namespace adroit::driver {

using adroit::shortNumber;  // a rejected 1e308 is logged as "1e+308", not as 309 digits

const char* verdictName(CommandVerdict v) {
  switch (v) {
    case CommandVerdict::kAccepted: return "accepted";
    case CommandVerdict::kClamped: return "clamped";
    case CommandVerdict::kBadAddressing: return "bad_addressing";
    case CommandVerdict::kUnknownName: return "unknown_name";
    case CommandVerdict::kIndexOutOfRange: return "index_out_of_range";
    case CommandVerdict::kDuplicate: return "duplicate";
    case CommandVerdict::kNotFinite: return "not_finite";
    case CommandVerdict::kOutOfRange: return "out_of_range";
    case CommandVerdict::kEmpty: return "empty";
  }
  return "?";
}

CheckedCommand checkCommand(const NameIndex& actuators, const std::vector<std::string>& names,
                            const std::vector<std::uint16_t>& indices, const std::vector<double>& values,
                            const ValueLimits& limits) {
  CheckedCommand out;
  std::vector<char> seen;
  checkCommand(actuators, names, indices, values, limits, &out, &seen);
  return out;
}

void checkCommand(const NameIndex& actuators, const std::vector<std::string>& names,
                  const std::vector<std::uint16_t>& indices, const std::vector<double>& values,
                  const ValueLimits& limits, CheckedCommand* out_ptr, std::vector<char>* seen_ptr) {
  CheckedCommand& out = *out_ptr;
  std::vector<char>& seen = *seen_ptr;
  // clear() keeps the storage: the next command reuses it.
  out.actuator.clear();
  out.value.clear();
  out.error.clear();
  auto fail = [&out](CommandVerdict v, std::string error) {
    out.verdict = v;
    out.error = std::move(error);
    out.actuator.clear();
    out.value.clear();
  };
  if (values.empty() && names.empty() && indices.empty()) return fail(CommandVerdict::kEmpty, "empty command");
  if (!names.empty() && !indices.empty())
    return fail(CommandVerdict::kBadAddressing, "both name[] and index[] are set; use exactly one");
  const std::size_t addressed = names.empty() ? indices.size() : names.size();
  if (addressed != values.size())
    return fail(CommandVerdict::kBadAddressing, "addresses " + std::to_string(addressed) + " actuators but carries " +
                                                    std::to_string(values.size()) + " values");
  seen.assign(actuators.size(), 0);
  for (std::size_t k = 0; k < values.size(); ++k) {
    int a;
    if (!names.empty()) {
      const auto found = actuators.find(names[k]);
      if (!found) return fail(CommandVerdict::kUnknownName, "unknown actuator '" + names[k] + "'");
      a = *found;
    } else {
      a = indices[k];
      if (a >= actuators.size())
        return fail(CommandVerdict::kIndexOutOfRange, "actuator index " + std::to_string(a) + " out of range [0, " +
                                                          std::to_string(actuators.size()) + ")");
    }
    if (seen[a]) return fail(CommandVerdict::kDuplicate, "actuator '" + actuators.name(a) + "' addressed twice");
    seen[a] = 1;
    out.actuator.push_back(a);
  }
  out.verdict = CommandVerdict::kAccepted;
  out.value.assign(values.begin(), values.end());
  for (std::size_t k = 0; k < values.size(); ++k) {
    const int a = out.actuator[k];
    const double v = values[k];
    if (!std::isfinite(v))
      return fail(CommandVerdict::kNotFinite, "non-finite value for '" + actuators.name(a) + "'");
    if (v < limits.lower[a] || (v > limits.upper[a] && !limits.clamp_above))
      return fail(CommandVerdict::kOutOfRange, "value " + shortNumber(v) + " for '" + actuators.name(a) +
                                                   "' outside [" + shortNumber(limits.lower[a]) + ", " +
                                                   shortNumber(limits.upper[a]) + "]");
    if (v > limits.upper[a]) {
      out.value[k] = limits.upper[a];
      out.verdict = CommandVerdict::kClamped;
    }
  }
}

}  // namespace adroit::driver
