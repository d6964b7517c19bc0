// Benchmarks of adroit_pneumatics (a program, not a test). Prints the tables and one
// RESULT line per required figure (DESIGN.md section 5):
//   1. plant step cost for 48 cylinders at the driver's 2 ms step
//   2. identification: 2 s open-loop prediction RMSE of the parametric model identified
//      from the plant model's data (noise and tube delay on), thesis table 4.5
//   3. tracking: iLQG vs PIDF on a locked leak-free cylinder and on the leaky moving M9
//      with the model identified on the locked one (thesis 5.6.2), figs. 5.15-5.17
//   4. pool timing: 1x48, 6x8, 12x4, 48x1 pools re-solving every 5 ms (fig. 5.20)
// Usage: pneumatics_bench [--quick]
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "adroit_core/timing_stats.h"
#include "adroit_pneumatics/excitation.h"
#include "adroit_pneumatics/plant.h"
#include "adroit_pneumatics/pressure_control.h"
#include "adroit_pneumatics/sensor_model.h"
#include "adroit_pneumatics/sysid.h"

using namespace adroit::pneumatics;

namespace {

constexpr double kTick = 0.005;    // control period (200 Hz)
constexpr double kSub = 0.0005;    // plant sub-step inside a tick
constexpr int kSubs = 10;
constexpr double kPi = 3.14159265358979323846;

void result(const std::string& name, double value, const char* unit, const char* op, double target) {
  bool pass = false;
  if (!std::strcmp(op, "<=")) pass = value <= target;
  else if (!std::strcmp(op, "<")) pass = value < target;
  else if (!std::strcmp(op, ">=")) pass = value >= target;
  std::printf("RESULT adroit_pneumatics/%s %.4g %s target %s %.4g %s\n", name.c_str(), value, unit, op, target,
              pass ? "PASS" : "FAIL");
}

// ---------------------------------------------------------------- 1. plant step cost
double plantStepMicros() {
  std::vector<CylinderSpec> specs(40, cylinderSpec("M9"));
  for (int i = 0; i < 8; ++i) specs.push_back(cylinderSpec("M24"));
  PneumaticPlant plant(specs, SupplyParams{}, 1);
  std::vector<double> u(48), x(48), v(48, 0.0);
  for (int i = 0; i < 48; ++i) x[i] = 0.5 * specs[i].stroke * (0.3 + 1.4 * i / 47.0);
  adroit::SampleStats blocks;
  const int steps = 2500;  // one block = 5 s of simulated time
  for (int b = 0; b < 20; ++b) {
    adroit::Stopwatch sw;
    for (int k = 0; k < steps; ++k) {
      if (k % 5 == 0 || k % 5 == 3)  // new 200 Hz command every 2.5 steps of 2 ms
        for (int i = 0; i < 48; ++i) u[i] = 2.5 * std::sin(0.013 * (b * steps + k) + 0.7 * i);
      plant.step(0.002, u.data(), x.data(), v.data());
    }
    blocks.add(sw.elapsed() / steps);
  }
  return blocks.summary().median * 1e6;
}

// ---------------------------------------------------------------- cylinder rigs
struct Rig {
  std::string name;
  bool leak = false;
  bool moving = false;
  std::uint64_t seed = 1;
};

// One M9 cylinder with its valve, tube delay, supply and sensors, stepped at kSub.
class Cylinder {
 public:
  explicit Cylinder(const Rig& rig)
      : rig_(rig), plant_(makePlant(rig)), sensor_(1, SensorParams{}, rig.seed + 100) {}

  double travel(double t) const {
    const double s = plant_.spec(0).stroke;
    return rig_.moving ? s * (0.5 + 0.3 * std::sin(2 * kPi * 1.3 * t) + 0.1 * std::sin(2 * kPi * 3.1 * t)) : 0.5 * s;
  }
  double travelRate(double t) const {
    const double s = plant_.spec(0).stroke;
    return rig_.moving ? s * (0.3 * 2 * kPi * 1.3 * std::cos(2 * kPi * 1.3 * t) + 0.1 * 2 * kPi * 3.1 * std::cos(2 * kPi * 3.1 * t))
                       : 0.0;
  }
  // Advances one control tick with command u; returns nothing, read measured()/truth().
  void tick(double u) {
    for (int s = 0; s < kSubs; ++s) {
      const double t = plant_.time();
      const double x = travel(t), xd = travelRate(t);
      plant_.step(kSub, &u, &x, &xd);
      sensor_.update(kSub, plant_.pressure(), {x});
    }
  }
  double time() const { return plant_.time(); }
  double measured() const { return sensor_.pressure()[0]; }
  double truth() const { return plant_.pressure()[0]; }
  ParametricInputs inputs() const {
    ParametricInputs in;
    const CylinderSpec& s = plant_.spec(0);
    in.volume = s.dead_volume + s.bore_area * travel(plant_.time());
    in.volume_rate = s.bore_area * travelRate(plant_.time());
    in.supply = plant_.supplyPressure();
    in.room = plant_.atmosphericPressure();
    return in;
  }

 private:
  static PneumaticPlant makePlant(const Rig& rig) {
    CylinderSpec s = cylinderSpec("M9");
    if (!rig.leak) s.leak_area = 0.0;
    PlantOptions o;
    o.initial_volts = -2.0;
    if (!rig.leak) o.area_spread = o.offset_spread = 0.0;
    return PneumaticPlant({s}, SupplyParams{}, rig.seed, o);
  }
  Rig rig_;
  PneumaticPlant plant_;
  SensorModel sensor_;
};

Recording record(const Rig& rig, const std::string& kind, double seconds, std::uint64_t seed) {
  ExcitationParams e;
  e.kind = kind;
  e.seed = seed;
  e.amplitude = 3.0;
  e.sweep_period = 20.0;
  Excitation ex(e);
  Cylinder c(rig);
  Recording r;
  r.dt = kTick;
  for (int k = 0; k < static_cast<int>(seconds / kTick); ++k) {
    const double u = ex.next(k * kTick, kTick);
    const ParametricInputs in = c.inputs();
    r.volts.push_back(u);
    r.pressure.push_back(c.measured());
    r.volume.push_back(in.volume);
    r.volume_rate.push_back(in.volume_rate);
    r.supply.push_back(in.supply);
    c.tick(u);
  }
  return r;
}

// ---------------------------------------------------------------- 3. tracking
struct Profile {
  std::string name;
  bool future_known;  // false: the whole future reference jumps without warning (5.6.2)
  double (*ref)(double t, std::uint64_t seed);
};

double sineRef(double t, std::uint64_t) { return 350e3 + 150e3 * std::sin(2 * kPi * 2.0 * t); }

// Smooth random: sum of sines with random phases below about 3 Hz.
double randomRef(double t, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> ph(0, 2 * kPi);
  double v = 0;
  const double freqs[] = {0.31, 0.57, 0.93, 1.41, 1.87, 2.43, 2.95};
  for (double f : freqs) v += std::sin(2 * kPi * f * t + ph(rng)) / (1.0 + f);
  return 350e3 + 75e3 * v;
}

// Piecewise constant: a new random level every 0.4 s.
double stepRef(double t, std::uint64_t seed) {
  const auto k = static_cast<std::uint64_t>(std::floor(t / 0.4));
  std::mt19937_64 rng(seed * 1000003ULL + k);
  return std::uniform_real_distribution<double>(150e3, 550e3)(rng);
}

struct Tracking {
  double rmse = 0;  // Pa
  double lag = 0;   // s
};

Tracking track(PressureController& ctl, const Rig& rig, const Profile& prof, double seconds, int horizon) {
  Cylinder c(rig);
  ctl.reset();
  std::vector<double> ref(horizon + 1), r_log, p_log;
  double w = -2.0;
  const int ticks = static_cast<int>(seconds / kTick);
  for (int k = 0; k < ticks; ++k) {
    const double t = k * kTick;
    for (int i = 0; i <= horizon; ++i)
      ref[i] = prof.ref(prof.future_known ? t + i * kTick : t, 7);  // unknown future: hold current
    double u = ctl.update(t, c.measured(), w, c.inputs(), ref.data(), horizon + 1, kTick, nullptr);
    if (!std::isfinite(u)) u = -5.0;  // never let a non-finite command reach the valve
    w = u;
    r_log.push_back(prof.ref(t, 7));
    p_log.push_back(c.truth());
    c.tick(u);
  }
  // Metrics after a 0.5 s start-up, on the true pressure at the tick rate.
  const std::size_t skip = static_cast<std::size_t>(0.5 / kTick);
  double sq = 0;
  std::size_t n = 0;
  for (std::size_t k = skip; k < r_log.size(); ++k, ++n) sq += (p_log[k] - r_log[k]) * (p_log[k] - r_log[k]);
  Tracking out;
  out.rmse = std::sqrt(sq / n);
  // Lag: shift maximising the cross-correlation of the mean-removed signals (0..300 ms).
  double mr = 0, mp = 0;
  for (std::size_t k = skip; k < r_log.size(); ++k) mr += r_log[k], mp += p_log[k];
  mr /= n, mp /= n;
  double best = -1e300;
  for (int lag = 0; lag <= 60; ++lag) {
    double acc = 0;
    for (std::size_t k = skip + lag; k < r_log.size(); ++k) acc += (r_log[k - lag] - mr) * (p_log[k] - mp);
    if (acc > best) best = acc, out.lag = lag * kTick;
  }
  return out;
}

// ---------------------------------------------------------------- 4. pool timing
struct PoolTiming {
  adroit::SampleStats solve, lag;
  int missed = 0;
};

PoolTiming poolTiming(const ParametricModel& model, int pools, double seconds) {
  const int total = 48, per = total / pools;
  std::vector<std::unique_ptr<IlqgPressureController>> ctl;
  for (int i = 0; i < total; ++i) ctl.push_back(std::make_unique<IlqgPressureController>(model, IlqgParams{}));
  std::mutex m;
  std::condition_variable cv;
  long cycle = 0;
  bool stop = false;
  std::vector<double> pressure(total, 2e5), command(total, 0.0);
  std::chrono::steady_clock::time_point stamp;
  std::vector<long> done(pools, 0);
  std::vector<PoolTiming> stats(pools);
  std::vector<std::thread> threads;
  for (int p = 0; p < pools; ++p) {
    threads.emplace_back([&, p] {
      long seen = 0;
      std::vector<double> ref(101);
      for (;;) {
        std::vector<double> state;
        std::chrono::steady_clock::time_point received;
        double t;
        {
          std::unique_lock<std::mutex> lock(m);
          cv.wait(lock, [&] { return stop || cycle > seen; });
          if (stop) return;
          seen = cycle;
          state = pressure;
          received = stamp;
          t = cycle * kTick;
        }
        adroit::Stopwatch sw;
        std::vector<double> out(per);
        for (int j = 0; j < per; ++j) {
          const int i = p * per + j;
          for (int k = 0; k <= 100; ++k) ref[k] = 350e3 + 150e3 * std::sin(2 * kPi * 2.0 * (t + k * kTick) + i);
          ParametricInputs in;
          in.volume = 1.2e-6;
          out[j] = ctl[i]->update(t, state[i], command[i], in, ref.data(), 101, kTick, nullptr);
        }
        const double solve = sw.elapsed();
        {
          std::lock_guard<std::mutex> lock(m);
          for (int j = 0; j < per; ++j) command[p * per + j] = out[j];
          done[p] = seen;
        }
        stats[p].solve.add(solve);
        stats[p].lag.add(std::chrono::duration<double>(std::chrono::steady_clock::now() - received).count());
      }
    });
  }
  const int cycles = static_cast<int>(seconds / kTick);
  auto next = std::chrono::steady_clock::now();
  int missed = 0;
  for (int c = 1; c <= cycles; ++c) {
    next += std::chrono::microseconds(5000);
    std::this_thread::sleep_until(next);
    {
      std::lock_guard<std::mutex> lock(m);
      // A pool that has not answered the previous cycle misses its re-solve.
      for (int p = 0; p < pools; ++p) missed += (done[p] < cycle) ? 1 : 0;
      for (int i = 0; i < total; ++i) pressure[i] = 350e3 + 150e3 * std::sin(2 * kPi * 2.0 * c * kTick + i);
      stamp = std::chrono::steady_clock::now();
      cycle = c;
    }
    cv.notify_all();
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  {
    std::lock_guard<std::mutex> lock(m);
    stop = true;
  }
  cv.notify_all();
  for (auto& th : threads) th.join();
  PoolTiming all;
  for (auto& s : stats) {
    for (double v : s.solve.samples()) all.solve.add(v);
    for (double v : s.lag.samples()) all.lag.add(v);
  }
  all.missed = missed;
  return all;
}

}  // namespace

int main(int argc, char** argv) {
  const bool quick = argc > 1 && std::string(argv[1]) == "--quick";
  std::printf("== adroit_pneumatics benchmark%s ==\n\n", quick ? " (quick)" : "");

  // 1. Plant cost.
  const double step_us = plantStepMicros();
  std::printf("Plant step, 40 x M9 + 8 x M24, dt 2 ms, new commands at 200 Hz: %.2f us per step (median of 20 blocks)\n\n",
              step_us);

  // 2. Identification on the leaky M9 (noise, tube delay, valve spread, piston motion on).
  const Rig airpel{"M9 leaky moving", true, true, 11};
  const Rig locked{"locked leak-free", false, false, 3};
  const double id_s = quick ? 30 : 60;
  adroit::Stopwatch fit_watch;
  const FitReport fit_airpel = fitParametricModel(record({"", true, false, 11}, "sweep", 40, 1),
                                                  record(airpel, "random", id_s, 2), true);
  const PredictionReport pred = predictionRmse(record(airpel, "random", 40, 9), ParametricModel(fit_airpel.params));
  const FitReport fit_locked = fitParametricModel(record(locked, "sweep", 40, 1), record(locked, "random", id_s, 2), false);
  const PredictionReport pred_locked = predictionRmse(record(locked, "random", 40, 9), ParametricModel(fit_locked.params));
  const double range = 620e3 - constants::kAtmosphere;
  std::printf("Identification (parametric model, 2 s open-loop windows, %% of working range %.0f kPa), fits took %.1f s\n",
              range / 1e3, fit_watch.elapsed());
  std::printf("  %-22s %10s %10s %8s\n", "cylinder", "RMSE kPa", "% range", "windows");
  std::printf("  %-22s %10.2f %10.2f %8d\n", "M9 leaky moving", pred.rmse / 1e3, pred.percent, pred.windows);
  std::printf("  %-22s %10.2f %10.2f %8d\n", "M9 locked leak-free", pred_locked.rmse / 1e3, pred_locked.percent,
              pred_locked.windows);
  const ParametricParams& q = fit_locked.params;
  std::printf("  locked model: c2 %.3f c3 %.3f c4 %.3f c7 %.1f c8 %.3f c9 %.2f cg %.3f\n\n", q.c2, q.c3, q.c4, q.c7,
              q.c8, q.c9, q.cg);

  // 3. Tracking. Model identified on the locked leak-free cylinder for both cases.
  const ParametricModel model(fit_locked.params);
  // PIDF gains: best mean RMSE over the three profiles on the locked cylinder (grid search).
  const Profile profiles[] = {{"sine 2 Hz", true, sineRef}, {"random", true, randomRef}, {"steps", false, stepRef}};
  const double seconds = quick ? 3.0 : 6.0;
  PidfParams best_pid;
  double best_score = 1e300;
  for (double kp : {1.0, 2.0, 3.0, 5.0, 8.0})
    for (double ki : {0.0, 10.0, 30.0, 80.0})
      for (double kd : {0.0, 0.01, 0.03}) {
        PidfParams prm;
        prm.kp = kp, prm.ki = ki, prm.kd = kd;
        PidfController pid(model, prm);
        double score = 0;
        for (const Profile& pr : profiles) score += track(pid, locked, pr, 3.0, 100).rmse;
        if (score < best_score) best_score = score, best_pid = prm;
      }
  std::printf("PIDF gains (grid search on the locked cylinder): kp %.1f V/MPa, ki %.1f V/(MPa s), kd %.3f V s/MPa, "
              "model feedforward\n\n", best_pid.kp, best_pid.ki, best_pid.kd);
  std::printf("Tracking (true pressure; lag = cross-correlation peak; limits +-2 V)\n");
  std::printf("  %-34s %-10s %12s %12s %9s %9s %7s\n", "case", "profile", "iLQG kPa", "PIDF kPa", "iLQG ms",
              "PIDF ms", "ratio");
  for (const Rig& rig : {locked, airpel}) {
    const std::string tag = rig.moving ? "robust" : "locked";
    for (const Profile& pr : profiles) {
      IlqgPressureController ilqg(model, IlqgParams{});
      PidfController pid(model, best_pid);
      const Tracking a = track(ilqg, rig, pr, seconds, 100);
      const Tracking b = track(pid, rig, pr, seconds, 100);
      const std::string label = rig.moving ? "robust: model locked, M9 leaky moving" : "locked leak-free M9";
      std::printf("  %-34s %-10s %12.2f %12.2f %9.1f %9.1f %7.2f\n", label.c_str(), pr.name.c_str(), a.rmse / 1e3,
                  b.rmse / 1e3, a.lag * 1e3, b.lag * 1e3, a.rmse / b.rmse);
      const std::string key = (pr.name == "sine 2 Hz" ? "sine" : pr.name) + "_" + tag;
      result("ilqg_pidf_rmse_ratio_" + key, a.rmse / b.rmse, "ratio", "<=", 0.7);
      result("ilqg_lag_" + key, a.lag * 1e3, "ms", "<", b.lag * 1e3);
    }
  }
  std::printf("\n");

  // 4. Pool timing.
  std::printf("Pool timing on %u cores: iLQG N=100, 2 iterations, every cylinder re-solved each 5 ms cycle\n",
              std::thread::hardware_concurrency());
  std::printf("  %-8s %-44s %-44s %7s\n", "pools", "solve per pool cycle (ms)", "policy lag state->command (ms)",
              "missed");
  double lag_p99_default = 0;
  int missed_default = 0;
  for (int pools : {1, 6, 12, 48}) {
    const PoolTiming t = poolTiming(model, pools, quick ? 1.0 : 3.0);
    std::printf("  %2dx%-5d %-44s %-44s %7d\n", pools, 48 / pools, adroit::formatSummary(t.solve.summary(), 1e3, "").c_str(),
                adroit::formatSummary(t.lag.summary(), 1e3, "").c_str(), t.missed);
    result("pool_policy_lag_p99_" + std::to_string(pools) + "x" + std::to_string(48 / pools), t.lag.summary().p99 * 1e3,
           "ms", "<=", 2.0);
    if (pools == 6) lag_p99_default = t.lag.summary().p99, missed_default = t.missed;
  }
  std::printf("\n");
  result("plant_step_48_us", step_us, "us", "<=", 3.0);
  result("sysid_prediction_rmse_pct_m9", pred.percent, "%", "<=", 3.0);
  result("pool_missed_resolves_6x8", missed_default, "cycles", "<=", 0);
  (void)lag_p99_default;
  return 0;
}
