// Distils a library of local TVLG policies into one neural-network policy (thesis 11.6): each
// local policy's stochastic controller runs `--rollouts` times from its own initial state on
// in-process simulation workers (SimRollouts, the task's scene), the network is regressed on
// the local policies' mean actions at the visited states, then `--dagger` rounds of DAgger
// (the network runs, the nearest local policy labels what it visits, retrain) follow.
//
// Usage: train_network_policy --library LIB --out NET [--task pickup]
//          [--observation full|partial|no_touch] [--layers 6] [--units 150] [--rollouts 50]
//          [--epochs 100] [--batch 256] [--learning-rate 1e-3] [--held-out 0.1]
//          [--dagger 0] [--dagger-rollouts 20] [--dagger-steps 0] [--seed 1] [--workers 0]
//          [--threads 1] [--tasks-dir DIR] [--description-dir DIR]
//
// Writes NET (the network policy file, atomically), NET.loss.csv (round, epoch, losses) and
// NET.loss.png (scripts/plot_network_loss.py; a plot that fails is one line, not an error).
// Prints each round's collection, about 20 epoch lines per round, a table of the rounds, and
// ends with the RESULT line (DESIGN.md section 5): the last round's held-out loss (normalised
// mean squared error over held-out whole rollouts) against the mean predictor's on the same
// held-out set:
//   RESULT adroit_learning/network_heldout_loss/<observation>_<layers>x<units> <v> normalised_mse target < <m> PASS|FAIL
//
// Bad input (an unknown observation set or task, layers or units out of range, a library file
// that readPolicyLibrary refuses or of another task, local policies that do not fit the task
// on this robot, an output directory that cannot be written) is one line on stderr and exit
// status 2 before anything runs. A failure while running (no rollout succeeded, the file
// cannot be written) is one line and status 1.
//
// --seed: the local policies' exploration noise, DAgger's random yaws, the network's initial
// weights, held-out split and batch order; a run is repeatable for a seed, --workers and
// --threads. --dagger-steps: control steps of each network rollout (0 = the task's horizon;
// beyond the local policies' horizon their last step labels the states).
// --threads: torch's intra-op threads while training (default 1: on the 2-core development
// machine under load, 2 threads trained 6 x 150 20-50 times slower than 1). --workers: the
// simulation workers (0 = one per core).
#include <adroit_core/command_line.h>
#include <adroit_core/run_program.h>
#include <adroit_core/timing_stats.h>
#include <adroit_description/scenes.h>
#include <adroit_learning/network_distillation.h>
#include <adroit_learning/sim_rollouts.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace {

const char* const kUsage =
    "usage: train_network_policy --library LIB --out NET [--task pickup] [--observation full|partial|no_touch] "
    "[--layers 6] [--units 150] [--rollouts 50] [--epochs 100] [--batch 256] [--learning-rate 1e-3] "
    "[--held-out 0.1] [--dagger 0] [--dagger-rollouts 20] [--dagger-steps 0] [--seed 1] [--workers 0] "
    "[--threads 1] [--tasks-dir DIR] [--description-dir DIR]";

[[noreturn]] void refuse(const std::string& why) {
  std::fprintf(stderr, "train_network_policy: %s\n", why.c_str());
  std::exit(2);
}

// "" when `out` can be written: its directory exists and is writable, and it is not a directory.
std::string outputProblem(const std::string& out) {
  namespace fs = std::filesystem;
  std::error_code error;
  if (fs::is_directory(out, error)) return "--out " + out + " is a directory";
  const fs::path parent = fs::path(out).parent_path();
  const std::string dir = parent.empty() ? "." : parent.string();
  if (!fs::is_directory(dir, error)) return "--out " + out + ": directory " + dir + " does not exist";
  if (::access(dir.c_str(), W_OK) != 0) return "--out " + out + ": directory " + dir + " is not writable";
  return "";
}

std::string yawList(const adroit::PolicyLibrary& library) {
  std::string text;
  char item[32];
  for (double yaw : library.yaws()) {
    std::snprintf(item, sizeof item, "%s%g", text.empty() ? "" : ", ", yaw);
    text += item;
  }
  return text;
}

// Prints the rounds' collection, a subsample of the epochs (first, last, every epochs/20-th)
// and each training's end.
adroit::DistillationProgressFn printer(int epochs) {
  const int every = std::max(1, epochs / 20);
  return [epochs, every](const adroit::DistillationProgress& p) {
    const adroit::DistillationRound& r = *p.summary;
    switch (p.stage) {
      case adroit::DistillationProgress::Stage::collected:
        std::printf("round %d: %d %s rollouts (%d failed%s%s), %d new samples, %.2f s\n", p.round,
                    r.collection.rollouts, p.round == 0 ? "local-policy" : "network", r.collection.failed,
                    r.collection.failed ? ", first: " : "", r.collection.first_failure.c_str(), r.collection.samples,
                    r.collect_seconds);
        break;
      case adroit::DistillationProgress::Stage::epoch:
        if (p.epoch == 1 || p.epoch == epochs || p.epoch % every == 0)
          std::printf("round %d epoch %5d/%d  train %.5f  held-out %.5f  (mean predictor %.5f)\n", p.round, p.epoch,
                      epochs, p.train_loss, p.held_out_loss, r.training.mean_predictor_held_out_loss);
        break;
      case adroit::DistillationProgress::Stage::trained:
        std::printf("round %d: trained on %d samples (%d held out) in %.2f s\n", p.round, r.training.train_samples,
                    r.training.held_out_samples, r.training.seconds);
        break;
    }
    std::fflush(stdout);
  };
}

void plotLoss(const std::string& csv, const std::string& png, const std::string& title) {
  const std::string script = "scripts/plot_network_loss.py";
  std::string path;
  try {
    path = adroit::description::packageShareDir("adroit_learning", script) + "/" + script;
  } catch (const std::exception& e) {
    std::printf("(plot not written: %s)\n", e.what());
    return;
  }
  adroit::ProgramOptions options;
  options.timeout_s = 60.0;
  options.quiet = true;
  const adroit::ProgramResult plot = adroit::runProgram({"/usr/bin/python3", path, csv, png, title}, options);
  if (plot.ok()) std::printf("wrote %s\n", png.c_str());
  else std::printf("(plot not written: %s)\n", plot.describe().c_str());
}

}  // namespace

int main(int argc, char** argv) {
  std::string library_path, out, task_name = "pickup", observation = "full", tasks_dir, description_dir;
  adroit::DistillationSettings settings;
  settings.training.threads = 1;
  long long layers = settings.spec.hidden_layers, units = settings.spec.units, rollouts = settings.rollouts_per_policy,
            epochs = settings.training.epochs, batch = settings.training.batch_size, dagger = 0,
            dagger_rollouts = settings.dagger_rollouts, dagger_steps = 0, seed = 1, workers = 0, threads = 1;
  adroit::CommandLine args(argc, argv, kUsage);
  while (args.next()) {
    if (args.is("--library")) library_path = args.text();
    else if (args.is("--out")) out = args.text();
    else if (args.is("--task")) task_name = args.text();
    else if (args.is("--observation")) observation = args.text();
    else if (args.is("--layers")) layers = args.integer();
    else if (args.is("--units")) units = args.integer();
    else if (args.is("--rollouts")) rollouts = args.integer();
    else if (args.is("--epochs")) epochs = args.integer();
    else if (args.is("--batch")) batch = args.integer();
    else if (args.is("--learning-rate")) settings.training.learning_rate = args.number();
    else if (args.is("--held-out")) settings.training.held_out_fraction = args.number();
    else if (args.is("--dagger")) dagger = args.integer();
    else if (args.is("--dagger-rollouts")) dagger_rollouts = args.integer();
    else if (args.is("--dagger-steps")) dagger_steps = args.integer();
    else if (args.is("--seed")) seed = args.integer();
    else if (args.is("--workers")) workers = args.integer();
    else if (args.is("--threads")) threads = args.integer();
    else if (args.is("--tasks-dir")) tasks_dir = args.text();
    else if (args.is("--description-dir")) description_dir = args.text();
    else args.unknown();
  }
  if (library_path.empty()) args.fail("--library is required");
  if (out.empty()) args.fail("--out is required");

  // Every count is range-checked as a long long before it becomes an int.
  const auto in = [](long long v, long long lo, long long hi) { return v >= lo && v <= hi; };
  if (!in(layers, 1, adroit::kMaxNetworkLayers))
    refuse("--layers must be in [1, " + std::to_string(adroit::kMaxNetworkLayers) + "], got " + std::to_string(layers));
  if (!in(units, 1, adroit::kMaxNetworkUnits))
    refuse("--units must be in [1, " + std::to_string(adroit::kMaxNetworkUnits) + "], got " + std::to_string(units));
  if (!in(rollouts, 1, adroit::kMaxDistillationRollouts))
    refuse("--rollouts must be in [1, " + std::to_string(adroit::kMaxDistillationRollouts) + "], got " +
           std::to_string(rollouts));
  if (!in(epochs, 1, 1000000)) refuse("--epochs must be in [1, 1000000], got " + std::to_string(epochs));
  if (!in(batch, 1, 1 << 20)) refuse("--batch must be in [1, 1048576], got " + std::to_string(batch));
  if (!in(dagger, 0, adroit::kMaxDaggerRounds))
    refuse("--dagger must be in [0, " + std::to_string(adroit::kMaxDaggerRounds) + "], got " + std::to_string(dagger));
  if (!in(dagger_rollouts, 1, adroit::kMaxDistillationRollouts))
    refuse("--dagger-rollouts must be in [1, " + std::to_string(adroit::kMaxDistillationRollouts) + "], got " +
           std::to_string(dagger_rollouts));
  if (!in(dagger_steps, 0, 1000000)) refuse("--dagger-steps must be in [0, 1000000], got " + std::to_string(dagger_steps));
  if (seed < 0) refuse("--seed must be >= 0, got " + std::to_string(seed));
  if (!in(workers, 0, 1024)) refuse("--workers must be in [0, 1024] (0 = one per core), got " + std::to_string(workers));
  if (!in(threads, 0, 1024)) refuse("--threads must be in [0, 1024] (0 = all cores), got " + std::to_string(threads));
  try {
    settings.observation = adroit::observationSetFromName(observation);
  } catch (const std::exception& e) {
    refuse(std::string("--observation: ") + e.what());
  }
  settings.spec.hidden_layers = static_cast<int>(layers);
  settings.spec.units = static_cast<int>(units);
  settings.rollouts_per_policy = static_cast<int>(rollouts);
  settings.training.epochs = static_cast<int>(epochs);
  settings.training.batch_size = static_cast<int>(batch);
  settings.training.threads = static_cast<int>(threads);
  settings.dagger_rounds = static_cast<int>(dagger);
  settings.dagger_rollouts = static_cast<int>(dagger_rollouts);
  settings.dagger_steps = static_cast<int>(dagger_steps);
  settings.seed = static_cast<std::uint64_t>(seed);
  settings.training.seed = static_cast<std::uint64_t>(seed);
  const std::string bad_settings = settings.validate();
  if (!bad_settings.empty()) refuse(bad_settings);
  const std::string bad_out = outputProblem(out);
  if (!bad_out.empty()) refuse(bad_out);

  adroit::TrainingTask task;
  adroit::PolicyLibrary library;
  std::unique_ptr<adroit::SimRollouts> sim;
  std::unique_ptr<adroit::StateLayout> layout;
  try {
    if (tasks_dir.empty())
      tasks_dir = adroit::description::packageShareDir("adroit_learning", "package.xml") + "/config/tasks";
    task = adroit::findTrainingTask(tasks_dir, task_name);
    library = adroit::readPolicyLibrary(library_path);
    if (library.task != task.name)
      refuse(library_path + ": a library of task '" + library.task + "', not '" + task.name + "'");
    if (description_dir.empty()) description_dir = adroit::description::descriptionShareDir();
    adroit::driver::SimConfig config;
    config.model_path = adroit::description::sceneFile(description_dir, task.scene, false);
    config.mode = adroit::driver::ActuationMode::kPneumatic;
    sim = std::make_unique<adroit::SimRollouts>(config, static_cast<int>(workers));
    layout = std::make_unique<adroit::StateLayout>(task, sim->jointNames(), sim->cylinderNames(), sim->hasObject());
  } catch (const std::exception& e) {
    refuse(e.what());
  }
  const std::string misfit = adroit::libraryProblem(library, task, *layout, *sim);
  if (!misfit.empty()) refuse(library_path + ": " + misfit);

  const std::string figure = observation + "_" + std::to_string(layers) + "x" + std::to_string(units);
  std::printf("train_network_policy: task %s (scene %s), library %s: %zu local policies (yaws %s deg), T %d x %.0f ms\n",
              task.name.c_str(), task.scene.c_str(), library_path.c_str(), library.entries.size(),
              yawList(library).c_str(), library.entries.front().policy->controller.horizon(), task.control_dt * 1e3);
  std::printf("network %s: nx %d, nu %d, touch sensors %zu; rollouts per policy %d, DAgger rounds %d x %d rollouts, "
              "epochs %d, simulation workers %d, training threads %d (0 = all cores), seed %lld\n",
              figure.c_str(), layout->nx(), layout->nu(), sim->touchNames().size(), settings.rollouts_per_policy,
              settings.dagger_rounds, settings.dagger_rollouts, settings.training.epochs, sim->workers(),
              settings.training.threads, seed);
  std::fflush(stdout);

  adroit::DistillationReport report;
  try {
    const adroit::NetworkPolicy policy =
        adroit::distillLibrary(*sim, task, *layout, library, settings, &report, printer(settings.training.epochs));
    adroit::writeNetworkPolicyFile(out, policy);
    adroit::writeFileAtomically(out + ".loss.csv", adroit::distillationLossCsv(report));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "train_network_policy: %s\n", e.what());
    return 1;
  }
  std::printf("wrote %s and %s.loss.csv\n", out.c_str(), out.c_str());
  plotLoss(out + ".loss.csv", out + ".loss.png", "network " + figure + " distilled from " + task.name);

  std::printf("\n%5s %9s %8s %8s %10s %10s %14s %10s %8s\n", "round", "rollouts", "failed", "samples", "train",
              "held-out", "mean predictor", "collect[s]", "train[s]");
  for (const adroit::DistillationRound& r : report.rounds)
    std::printf("%5d %9d %8d %8d %10.5f %10.5f %14.5f %10.2f %8.2f\n", r.round, r.collection.rollouts,
                r.collection.failed, r.dataset_samples, r.trainLoss(), r.heldOutLoss(),
                r.training.mean_predictor_held_out_loss, r.collect_seconds, r.train_seconds);
  const adroit::DistillationRound& last = report.rounds.back();
  std::printf("final held-out loss %.5f, mean predictor %.5f (normalised MSE, %d held-out samples), %.1f s in all\n",
              last.heldOutLoss(), last.training.mean_predictor_held_out_loss, last.training.held_out_samples,
              report.seconds);
  std::printf("%s\n", adroit::resultLine("adroit_learning", "network_heldout_loss/" + figure, last.heldOutLoss(),
                                         "normalised_mse", "<", last.training.mean_predictor_held_out_loss)
                          .c_str());
  return 0;
}
