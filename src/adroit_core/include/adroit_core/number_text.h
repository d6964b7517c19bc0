// A number as an error or log line shows it: six significant digits ("%g"), so 1e308 is
// "1e+308", not the 309 digits std::to_string writes, and 0.05 is "0.05", not "0.050000".
#pragma once

#include <cstdio>
#include <string>

namespace adroit {

inline std::string shortNumber(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", value);
  return text;
}

}  // namespace adroit
