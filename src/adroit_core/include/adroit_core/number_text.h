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

// A number as a file keeps it: 17 significant digits ("%.17g"), which read back to the same
// double (policy, library and network files).
inline std::string exactNumber(double value) {
  char text[40];
  std::snprintf(text, sizeof text, "%.17g", value);
  return text;
}

}  // namespace adroit
