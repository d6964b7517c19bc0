// kl_update: one KL-constrained update of a time-varying linear-Gaussian controller
// (adroit_learning/kl_update.h) on text files in the MatrixFile format (matrix_file.h,
// README.md).
//
// Usage:
//   kl_update --dynamics DYN.txt --cost COST.txt --controller PREV.txt --epsilon EPS
//             --out NEW.txt [--eta-init ETA] [--eta-min ETA] [--eta-max ETA]
//
// DYN.txt: dims (1x3: nx nu T), x0_mean, x0_cov, Fx.t, Fu.t, f.t, Sigma.t (t = 0..T-1).
// COST.txt: cxx.t, cx.t (t = 0..T, T terminal), cuu.t, cux.t, cu.t (t = 0..T-1).
// PREV.txt: dims, K.t, k.t, C.t (t = 0..T-1).
// NEW.txt: the new controller in PREV.txt's format plus 1x1 blocks eta, kl, predicted_cost,
// converged (1 or 0) and iterations; it can be passed back as --controller.
// Exit status: 0 written (a not converged update is written too, with a warning on stderr),
// 1 bad arguments or input file (the message names the file and the block), 2 no update.
#include <cstdlib>
#include <iostream>
#include <string>

#include "adroit_learning/kl_update.h"
#include "adroit_learning/matrix_file.h"

namespace {

int usage(const std::string& problem) {
  std::cerr << "kl_update: " << problem << "\n"
            << "usage: kl_update --dynamics DYN.txt --cost COST.txt --controller PREV.txt --epsilon EPS --out NEW.txt"
               " [--eta-init ETA] [--eta-min ETA] [--eta-max ETA]\n";
  return 1;
}

bool parsePositive(const std::string& s, double& out) {
  char* end = nullptr;
  out = std::strtod(s.c_str(), &end);
  return end != s.c_str() && *end == '\0' && out > 0 && out < 1e300;
}

}  // namespace

int main(int argc, char** argv) {
  std::string dynamics_path, cost_path, controller_path, out_path;
  double epsilon = 0;
  adroit::KlUpdateSettings settings;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (i + 1 >= argc) return usage("missing value after " + arg);
    const std::string value = argv[++i];
    double number = 0;
    const bool is_number = parsePositive(value, number);
    if (arg == "--dynamics")
      dynamics_path = value;
    else if (arg == "--cost")
      cost_path = value;
    else if (arg == "--controller")
      controller_path = value;
    else if (arg == "--out")
      out_path = value;
    else if (arg == "--epsilon" || arg == "--eta-init" || arg == "--eta-min" || arg == "--eta-max") {
      if (!is_number) return usage(arg + " needs a positive number, got '" + value + "'");
      (arg == "--epsilon" ? epsilon : arg == "--eta-init" ? settings.eta_init
                                    : arg == "--eta-min" ? settings.eta_min
                                                         : settings.eta_max) = number;
    } else {
      return usage("unknown argument " + arg);
    }
  }
  if (dynamics_path.empty() || cost_path.empty() || controller_path.empty() || out_path.empty() || epsilon <= 0)
    return usage("--dynamics, --cost, --controller, --epsilon and --out are required");
  if (settings.eta_min > settings.eta_max) return usage("--eta-min is above --eta-max");

  adroit::LgDynamics dyn;
  adroit::QuadraticCost cost;
  adroit::LgController prev;
  try {
    dyn = adroit::readDynamics(adroit::MatrixFile::read(dynamics_path));
    cost = adroit::readCost(adroit::MatrixFile::read(cost_path), dyn.nx, dyn.nu, dyn.horizon);
    prev = adroit::readController(adroit::MatrixFile::read(controller_path), dyn.nx, dyn.nu, dyn.horizon);
  } catch (const adroit::MatrixFileError& e) {
    std::cerr << "kl_update: " << e.what() << "\n";
    return 1;
  }

  adroit::KlUpdateResult result;
  try {
    adroit::KlUpdate update(dyn.nx, dyn.nu, dyn.horizon);
    result = update.update(dyn, cost, prev, epsilon, settings);
  } catch (const std::exception& e) {
    std::cerr << "kl_update: " << e.what() << "\n";
    return 2;
  }
  if (!result.converged)
    std::cerr << "kl_update: warning: KL " << result.kl << " not within the tolerance of epsilon " << epsilon
              << " after " << result.iterations << " iterations (eta " << result.eta << ")\n";

  adroit::MatrixFile out(out_path);
  adroit::writeController(result.controller, out);
  out.set("eta", Eigen::MatrixXd::Constant(1, 1, result.eta));
  out.set("kl", Eigen::MatrixXd::Constant(1, 1, result.kl));
  out.set("predicted_cost", Eigen::MatrixXd::Constant(1, 1, result.predicted_cost));
  out.set("converged", Eigen::MatrixXd::Constant(1, 1, result.converged ? 1.0 : 0.0));
  out.set("iterations", Eigen::MatrixXd::Constant(1, 1, result.iterations));
  try {
    out.write(out_path);
  } catch (const adroit::MatrixFileError& e) {
    std::cerr << "kl_update: " << e.what() << "\n";
    return 1;
  }
  std::cout << "eta " << result.eta << " kl " << result.kl << " predicted_cost " << result.predicted_cost
            << (result.converged ? "" : " (not converged)") << "\n";
  return 0;
}
