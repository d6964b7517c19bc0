// pneumatic_sysid: fits the parametric pressure model from CSV recordings and writes the
// parameter YAML the pools load.
//   pneumatic_sysid --sweep sweep.csv --random random.csv [--test test.csv] [--volume] --out model.yaml
// CSV columns: t,volts,pressure,volume,volume_rate,supply (SI). Reports the 2 s open-loop
// prediction RMSE (% of the working range) on --test (default: the random recording).
#include <cstdio>
#include <cstring>
#include <exception>
#include <string>

#include "adroit_pneumatics/params_io.h"
#include "adroit_pneumatics/sysid.h"

using namespace adroit::pneumatics;

int main(int argc, char** argv) {
  std::string sweep, random, test, out;
  bool volume = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](std::string& dst) {
      if (i + 1 >= argc) { std::fprintf(stderr, "pneumatic_sysid: %s needs a value\n", a.c_str()); std::exit(2); }
      dst = argv[++i];
    };
    if (a == "--sweep") value(sweep);
    else if (a == "--random") value(random);
    else if (a == "--test") value(test);
    else if (a == "--out") value(out);
    else if (a == "--volume") volume = true;
    else { std::fprintf(stderr, "pneumatic_sysid: unknown argument %s\n", a.c_str()); return 2; }
  }
  if (sweep.empty() || random.empty() || out.empty()) {
    std::fprintf(stderr, "usage: pneumatic_sysid --sweep sweep.csv --random random.csv [--test test.csv] [--volume] --out model.yaml\n");
    return 2;
  }
  try {
    const Recording rs = readRecordingCsv(sweep), rr = readRecordingCsv(random);
    const FitReport fit = fitParametricModel(rs, rr, volume);
    const Recording rt = test.empty() ? rr : readRecordingCsv(test);
    const PredictionReport pred = predictionRmse(rt, ParametricModel(fit.params));
    ParameterSet set;
    set.defaults = fit.params;
    saveParameterSet(out, set);
    std::printf("steady-state fit RMSE %.2f kPa, segment fit RMSE %.2f kPa, dead time %.2f ms\n", fit.steady_rmse / 1e3,
                fit.segment_rmse / 1e3, fit.params.td * 1e3);
    std::printf("2 s prediction RMSE %.2f kPa = %.2f %% of the working range over %d windows\n", pred.rmse / 1e3,
                pred.percent, pred.windows);
    std::printf("wrote %s\n", out.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "pneumatic_sysid: %s\n", e.what());
    return 1;
  }
  return 0;
}
