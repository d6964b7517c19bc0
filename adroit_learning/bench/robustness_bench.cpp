// Exploration and robustness benchmark (issue 13; thesis 8.5, figures 8.5 and 8.6), in
// simulation with the in-process workers, one run:
//
//  1. Noise smoothing (fig. 8.5): the rotation task trained from scratch with exploration noise
//     smoothed by Gaussian kernels of several widths (0 = white noise), over several seeds.
//     Printed: cost per iteration and a summary per width (cost at iterations 0 / 5 / 10 /
//     last, best, cost rises, sample drops). Baseline: white noise, in the same run.
//  2. Delayed robustification (8.5.1, fig. 8.6): per seed, one controller trained without
//     initial-state noise and one with noise of level `--train-noise` from iteration
//     `--noise-from` on (the thesis: about 2.5 % from iteration 10), same seed, same iterations.
//     Each final controller then runs without exploration noise from 20 perturbed initial
//     states at each of 5 / 10 / 20 % of every joint's range (the same perturbations for both)
//     and once unperturbed. Printed: drops and angle error per level.
//
// Writes <out>/smoothing.csv, <out>/robustness.csv (angle about the rotation axis per step and
// trial), <out>/robustness_table.csv, and through plot_robustness.py smoothing.png and
// robustness.png. Ends with RESULT lines (drops of the robust vs the plain controller).
//
// Usage: robustness_bench [--task T] [--iterations N] [--seeds S] [--widths 0,1,2,4]
//                         [--trials N] [--train-noise L] [--noise-from I] [--workers W] [--out DIR]
#include <adroit_core/command_line.h>
#include <adroit_core/run_program.h>
#include <adroit_description/scenes.h>
#include <adroit_learning/sim_rollouts.h>
#include <adroit_learning/trainer.h>

#include <sys/stat.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

namespace {

std::vector<double> splitNumbers(const std::string& s) {
  std::vector<double> out;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');)
    if (!item.empty()) out.push_back(std::atof(item.c_str()));
  return out;
}

// Trains one controller from scratch, printing a compact line per iteration.
std::unique_ptr<adroit::Trainer> train(const adroit::TrainingTask& task, const adroit::TrainerSettings& settings,
                                       adroit::RolloutBackend& backend, const std::string& label) {
  auto trainer = std::make_unique<adroit::Trainer>(task, settings, backend);
  std::printf("%-24s", label.c_str());
  while (!trainer->finished()) {
    const adroit::IterationReport r = trainer->iterate();
    if (!r.ok) std::printf(" [%d failed: %s]", r.iteration, r.message.c_str());
    else std::printf(" %.0f%s", r.cost_mean, r.drops > 0 ? std::string(r.drops, '*').c_str() : "");
    std::fflush(stdout);
  }
  std::printf("\n");
  return trainer;
}

double costAt(const std::vector<adroit::IterationReport>& h, int i) {
  return i < static_cast<int>(h.size()) && h[i].ok ? h[i].cost_mean : NAN;
}

struct Trial {
  bool dropped = false;
  double angle_error = 0;
  std::vector<double> angle;  // about the task's rotation axis, per control step (T + 1)
};

// Runs the controller's mean (no exploration noise) from each initial joint offset.
std::vector<Trial> evaluate(adroit::RolloutBackend& backend, const adroit::Trainer& trainer,
                            const std::vector<std::vector<double>>& offsets) {
  const auto& task = trainer.task();
  std::vector<adroit::RolloutRequest> requests(offsets.size());
  for (std::size_t i = 0; i < offsets.size(); ++i) {
    requests[i].noise = Eigen::MatrixXd::Zero(trainer.layout().nu(), task.horizon);
    requests[i].joint_offset = offsets[i];
  }
  const std::atomic<bool> no_cancel{false};
  const auto results = backend.run(task, trainer.layout(), trainer.controller(), requests, no_cancel);
  std::vector<Trial> trials;
  for (const auto& r : results) {
    Trial t;
    if (!r.ok) {  // a failed rollout (non-finite state, safe state) counts as a drop
      std::printf("  evaluation rollout failed: %s\n", r.error.c_str());
      t.dropped = true;
      t.angle_error = NAN;
      trials.push_back(t);
      continue;
    }
    const adroit::TaskOutcome o = trainer.cost().outcome(r.sample);
    t.dropped = o.dropped;
    t.angle_error = o.angle_error;
    for (int s = 0; s < r.sample.x.cols(); ++s) t.angle.push_back(trainer.cost().objectAngle(r.sample.x.col(s)));
    trials.push_back(t);
  }
  return trials;
}

int drops(const std::vector<Trial>& trials) {
  return static_cast<int>(std::count_if(trials.begin(), trials.end(), [](const Trial& t) { return t.dropped; }));
}

double meanAngleError(const std::vector<Trial>& trials) {  // over the trials that kept the object
  double sum = 0;
  int n = 0;
  for (const auto& t : trials)
    if (!t.dropped) sum += t.angle_error, ++n;
  return n > 0 ? sum / n : NAN;
}

}  // namespace

int main(int argc, char** argv) {
  std::string task_name = "rotate_vertical_cw", out = "robustness_bench_out";
  int iterations = 20, seeds = 3, trials = 20, workers = 0, noise_from = 10;
  double train_noise = 0.025;
  std::vector<double> widths = {0, 1, 2, 4};
  const std::vector<double> levels = {0.05, 0.10, 0.20};
  adroit::CommandLine args(argc, argv,
                           "usage: robustness_bench [--task T] [--iterations N] [--seeds S] [--widths 0,1,2,4] "
                           "[--trials N] [--train-noise L] [--noise-from I] [--workers W] [--out DIR]");
  while (args.next()) {
    if (args.is("--task")) task_name = args.text();
    else if (args.is("--iterations")) iterations = static_cast<int>(args.integer());
    else if (args.is("--seeds")) seeds = static_cast<int>(args.integer());
    else if (args.is("--widths")) widths = splitNumbers(args.text());
    else if (args.is("--trials")) trials = static_cast<int>(args.integer());
    else if (args.is("--train-noise")) train_noise = args.number();
    else if (args.is("--noise-from")) noise_from = static_cast<int>(args.integer());
    else if (args.is("--workers")) workers = static_cast<int>(args.integer());
    else if (args.is("--out")) out = args.text();
    else args.unknown();
  }
  if (seeds < 1 || trials < 1 || widths.empty() || noise_from >= iterations)
    args.fail("seeds and trials must be positive, widths non-empty, and --noise-from below --iterations");
  const std::string tasks_dir =
      adroit::description::packageShareDir("adroit_learning", "config/tasks/position_with_gravity.yaml") +
      "/config/tasks";
  const adroit::TrainingTask task = adroit::findTrainingTask(tasks_dir, task_name);
  if (!task.uses_object()) {
    std::fprintf(stderr, "robustness_bench: task %s has no object to drop\n", task_name.c_str());
    return 2;
  }
  adroit::driver::SimConfig config;
  config.model_path = adroit::description::sceneFile(adroit::description::descriptionShareDir(), task.scene, false);
  config.mode = adroit::driver::ActuationMode::kPneumatic;
  adroit::SimRollouts sim(config, workers);
  ::mkdir(out.c_str(), 0755);
  adroit::TrainerSettings base;
  base.iterations = iterations;
  base.samples = 5;
  std::printf("task %s: %d iterations x %d rollouts, %d seeds, %d workers; per iteration: sample cost mean "
              "(* = one sample dropped the object)\n",
              task_name.c_str(), iterations, base.samples, seeds, sim.workers());

  // 1. Noise smoothing.
  std::printf("\n== noise smoothing (fig. 8.5): kernel width in control steps\n");
  std::ofstream smoothing_csv(out + "/smoothing.csv");
  smoothing_csv << "width,seed,iteration,cost_mean,cost_std,drops,angle_error\n";
  struct WidthSummary {
    double width;
    std::vector<double> c0, c5, c10, last, best;
    int rises = 0, sample_drops = 0;
  };
  std::vector<WidthSummary> summary;
  for (double width : widths) {
    WidthSummary s{width, {}, {}, {}, {}, {}};
    for (int seed = 1; seed <= seeds; ++seed) {
      adroit::TrainerSettings settings = base;
      settings.smoothing_width = width;
      settings.seed = seed;
      char label[64];
      std::snprintf(label, sizeof(label), "width %.1f seed %d", width, seed);
      const auto trainer = train(task, settings, sim, label);
      const auto& h = trainer->history();
      double best = 1e300;
      for (std::size_t i = 0; i < h.size(); ++i) {
        smoothing_csv << width << ',' << seed << ',' << i << ',' << h[i].cost_mean << ',' << h[i].cost_std << ','
                      << h[i].drops << ',' << h[i].angle_error_mean << '\n';
        if (h[i].ok) best = std::min(best, h[i].cost_mean);
        s.sample_drops += h[i].drops;
        // A rise: the sample cost grew by more than a quarter over the previous iteration's.
        if (i > 0 && h[i].ok && h[i - 1].ok && h[i].cost_mean > 1.25 * h[i - 1].cost_mean) ++s.rises;
      }
      s.c0.push_back(costAt(h, 0));
      s.c5.push_back(costAt(h, 5));
      s.c10.push_back(costAt(h, 10));
      s.last.push_back(costAt(h, iterations - 1));
      s.best.push_back(best);
    }
    summary.push_back(s);
  }
  const auto mean = [](const std::vector<double>& v) {
    double sum = 0;
    for (double x : v) sum += x;
    return v.empty() ? NAN : sum / v.size();
  };
  std::printf("\n%-8s %10s %10s %10s %10s %10s %12s %14s   (means over %d seeds)\n", "width", "cost it0", "it5", "it10",
              "last", "best", "cost rises", "sample drops", seeds);
  for (const auto& s : summary)
    std::printf("%-8.1f %10.1f %10.1f %10.1f %10.1f %10.1f %12d %14d\n", s.width, mean(s.c0), mean(s.c5), mean(s.c10),
                mean(s.last), mean(s.best), s.rises, s.sample_drops);

  // 2. Delayed robustification.
  std::printf("\n== delayed robustification (fig. 8.6): initial-state noise %.1f %% of each joint's range from "
              "iteration %d vs none\n",
              train_noise * 100, noise_from);
  std::vector<std::vector<std::vector<double>>> offsets(levels.size());  // per level, per trial
  adroit::NormalNoise offset_rng(20261123);
  for (std::size_t l = 0; l < levels.size(); ++l)
    for (int i = 0; i < trials; ++i) offsets[l].push_back(adroit::initialStateOffsets(offset_rng, sim.jointRanges(), levels[l]));
  std::ofstream angle_csv(out + "/robustness.csv");
  angle_csv << "controller,seed,level,trial,step,angle,dropped\n";
  std::ofstream table_csv(out + "/robustness_table.csv");
  table_csv << "controller,seed,level,trials,drops,angle_error\n";
  const char* names[2] = {"plain", "robust"};
  std::vector<std::vector<int>> total_drops(2, std::vector<int>(levels.size(), 0));
  std::vector<std::vector<double>> total_error(2, std::vector<double>(levels.size(), 0));
  std::vector<std::string> rows;  // printed after the training lines
  for (int seed = 1; seed <= seeds; ++seed) {
    for (int c = 0; c < 2; ++c) {
      adroit::TrainerSettings settings = base;
      settings.seed = seed;
      if (c == 1) settings.initial_state_noise = train_noise, settings.initial_state_noise_from = noise_from;
      const auto trainer = train(task, settings, sim, std::string(names[c]) + " seed " + std::to_string(seed));
      const std::vector<Trial> nominal = evaluate(sim, *trainer, {{}});
      char row[512];
      int n = std::snprintf(row, sizeof(row), "%-8s %-5d %8.3f %s", names[c], seed, nominal[0].angle_error,
                            nominal[0].dropped ? "drop " : "held ");
      for (std::size_t s = 0; s < nominal[0].angle.size(); ++s)
        angle_csv << names[c] << ',' << seed << ",0,0," << s << ',' << nominal[0].angle[s] << ',' << nominal[0].dropped
                  << '\n';
      for (std::size_t l = 0; l < levels.size(); ++l) {
        const std::vector<Trial> result = evaluate(sim, *trainer, offsets[l]);
        const int d = drops(result);
        const double err = meanAngleError(result);
        total_drops[c][l] += d;
        total_error[c][l] += err / seeds;
        n += std::snprintf(row + n, sizeof(row) - n, "   %8d/%-3d %6.3f", d, trials, err);
        table_csv << names[c] << ',' << seed << ',' << levels[l] << ',' << trials << ',' << d << ',' << err << '\n';
        for (int i = 0; i < trials; ++i)
          for (std::size_t s = 0; s < result[i].angle.size(); ++s)
            angle_csv << names[c] << ',' << seed << ',' << levels[l] << ',' << i << ',' << s << ',' << result[i].angle[s]
                      << ',' << result[i].dropped << '\n';
      }
      rows.push_back(row);
    }
  }
  std::printf("\n%-8s %-5s %14s", "trained", "seed", "unperturbed");
  for (double level : levels) std::printf("   %3.0f %%: drops  error", level * 100);
  std::printf("\n");
  for (const auto& r : rows) std::printf("%s\n", r.c_str());
  angle_csv.close();
  table_csv.close();
  smoothing_csv.close();

  const std::string script = "scripts/plot_robustness.py";
  const adroit::ProgramResult plot = adroit::runProgram(
      {"/usr/bin/python3", adroit::description::packageShareDir("adroit_learning", script) + "/" + script, out});
  if (!plot.ok()) std::printf("(plots not written: %s)\n", plot.describe().c_str());

  const WidthSummary& white = summary.front();
  for (const auto& s : summary)
    std::printf("RESULT smoothing_width_%.1f_best_cost %.1f last %.1f rises %d sample_drops %d (width %.1f: best %.1f "
                "last %.1f rises %d sample_drops %d; means over %d seeds)\n",
                s.width, mean(s.best), mean(s.last), s.rises, s.sample_drops, white.width, mean(white.best),
                mean(white.last), white.rises, white.sample_drops, seeds);
  const int all = seeds * trials;
  bool fewer_everywhere = true;
  for (std::size_t l = 0; l < levels.size(); ++l) {
    const bool fewer = total_drops[1][l] < total_drops[0][l] || (total_drops[0][l] == 0 && total_drops[1][l] == 0);
    fewer_everywhere = fewer_everywhere && fewer;
    std::printf("RESULT robustification_drops_at_%.0f_percent %d/%d (plain %d/%d); angle error %.3f rad (plain %.3f) %s\n",
                levels[l] * 100, total_drops[1][l], all, total_drops[0][l], all, total_error[1][l], total_error[0][l],
                !fewer ? "FAIL" : total_drops[0][l] == 0 ? "PASS (neither dropped)" : "PASS");
  }
  std::printf("RESULT robustification %s: the controller trained with delayed initial-state noise drops the object "
              "less often at every level\n",
              fewer_everywhere ? "PASS" : "FAIL");
  return 0;
}
