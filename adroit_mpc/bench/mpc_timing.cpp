// Behaviour MPC timing on the bottle catch scene (thesis table 6.2) and contact pruning
// (thesis 6.4.3). A program, not a test: run it on an idle machine.
//
//   mpc_timing [--iterations N] [--dt S] [--skip K] [--quick] [--compare-only]
//              [--paths-only] [--blocks N] [--max-age S] [--reuse-tolerance X]
//              [--planners ilqg,sampling,cem] [--tasks catch,relocate,type]
//              [--samples N] [--cem-elites N] [--cem-std-initial S] [--cem-std-min S]
//
// 1. Cost of one step and of one finite-difference knot on the planning model, sensors on/off;
//    grouped finite differences (separated trees nudged together) against mjd_transitionFD.
// 2. iLQG (and predictive sampling in the same run) in closed loop on the bottle drop:
//    the simulation (bottle.xml, 2 ms) runs the policy for one control period between two
//    optimisations; per-phase time split, median and p90.
// 2a. The derivative path before issue 38 (every knot of the skip pattern at every call, one
//    nudge per control) against the shipped one (derivatives reused across calls up to
//    --max-age, B through the generalised forces), alternating blocks of the closed loop;
//    CPU seconds per iteration of each and their ratio (--paths-only: this table alone).
// 2b. The planners side by side on every task (its scene and its YAML's planner hints):
//    wall and CPU time per iteration, CPU against iLQG's (--compare-only: this table alone).
//    --samples and the --cem-* flags set the sampling planners' settings for it.
// 3. Design choices: iLQG total for planner dt, derivative_skip and worker count.
// 4. Active contacts per step, before and after pruning, over a falling-bottle rollout.
// 5. What a cheaper planning model (fixed tendons with constant moment arms instead of the
//    wrapped spatial tendons) would give: step and FD time, built in memory from the XML.
// Ends with RESULT lines (DESIGN.md §5).
#include <adroit_core/command_line.h>
#include <adroit_core/mujoco_model.h>
#include <adroit_core/model_tables.h>
#include <adroit_core/timing_stats.h>
#include <adroit_core/word_list.h>
#include <adroit_description/scenes.h>
#include <adroit_mpc/fd_derivatives.h>
#include <adroit_mpc/planner.h>
#include <adroit_mpc/planning_model.h>
#include <adroit_mpc/task.h>
#include <adroit_mpc/task_params.h>

#include <algorithm>
#include <array>

#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

using namespace adroit_mpc;

namespace {

// CPU time of the whole process (every thread), s: independent of how many cores other
// programs leave us, so it shows what an idle machine would give (CPU / cores, roughly).
double processCpuSeconds() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

struct Series {
  std::vector<double> rollout, derivatives, cost, backward, line_search, total, cpu, knots;
  void add(const OptimizeReport& r, double cpu_seconds) {
    cpu.push_back(cpu_seconds);
    knots.push_back(r.derivative_knots);
    rollout.push_back(r.rollout);
    derivatives.push_back(r.derivatives);
    cost.push_back(r.cost);
    backward.push_back(r.backward);
    line_search.push_back(r.line_search);
    total.push_back(r.total);
  }
};

double ms(const std::vector<double>& v, double p) { return 1e3 * adroit::percentile(v, p); }

double mean(const std::vector<double>& v) {
  double sum = 0;
  for (double x : v) sum += x;
  return v.empty() ? 0 : sum / v.size();
}

void append(std::vector<double>& to, const std::vector<double>& from) { to.insert(to.end(), from.begin(), from.end()); }

struct RunResult {
  Series series;
  double final_error = 0, min_object_z = 0;
  int diverged = 0;
};

struct Scene {
  std::string share, planning_file, sim_file;
};

// A task's closed loop: its scene, the planning model's contact settings as the node sets
// them (typing: 1 mm), the object dropped from its start, a goal or a sequence midway.
struct TaskSetup {
  std::string task, planning_file, sim_file;
  double contact = -1;  // planning model's contact margin and softness (-1: keep)
};

TaskSetup taskSetup(const std::string& share, const std::string& task) {
  const std::string scene = paramString(task, defaultTaskParams(task), "scene");
  return {task, adroit::description::sceneFile(share, scene, true), adroit::description::sceneFile(share, scene, false),
          task == "type" ? 0.001 : -1};
}

// `base` with the planner hints of the task's YAML (horizon, knot spacing, derivative skip).
PlannerSettings taskSettings(const std::string& task, PlannerSettings base) {
  const TaskParams d = defaultTaskParams(task);
  base.horizon = paramNumber(task, d, "horizon", 0.01, 5);
  base.dt = paramNumber(task, d, "planner_dt", 1e-4, 0.1);
  if (d.numbers.count("derivative_skip"))
    base.derivative_skip = static_cast<int>(paramNumber(task, d, "derivative_skip", 1, 100));
  return base;
}

// The simulation at the rest keyframe with the task's object at its start, at rest.
void startTrial(const std::string& task, const mjModel* m, mjData* d) {
  const int rest = mj_name2id(m, mjOBJ_KEY, "rest");
  if (rest >= 0) mj_resetDataKeyframe(m, d, rest);
  const TaskParams p = defaultTaskParams(task);
  const int object = mj_name2id(m, mjOBJ_BODY, "object");
  if (object >= 0 && m->body_jntnum[object] == 1 && p.vectors.count("object_start_position")) {
    const int joint = m->body_jntadr[object];
    const Eigen::Vector3d start = paramVector3(task, p, "object_start_position");
    double* q = d->qpos + m->jnt_qposadr[joint];
    for (int i = 0; i < 3; ++i) q[i] = start[i];
    q[3] = 1, q[4] = q[5] = q[6] = 0;
    mju_zero(d->qvel + m->jnt_dofadr[joint], 6);
  }
  mj_forward(m, d);
}

// Midway through the loop: relocation gets a goal 5 cm beside the hold, typing its keys.
void giveTaskWork(Task& task) {
  std::string why;
  if (task.name() == "relocate") {
    const Eigen::Vector3d hold = paramVector3("relocate", defaultTaskParams("relocate"), "hold_position");
    if (!task.setGoal(hold + Eigen::Vector3d(0.05, 0, 0), Eigen::Quaterniond::Identity(), &why))
      throw std::runtime_error("relocate goal: " + why);
  }
  if (task.name() == "type" && !task.setSequence("1234567890", &why)) throw std::runtime_error("type: " + why);
}

// Closed loop: plan from the simulation's state, run the policy for `period`, repeat.
RunResult runClosedLoop(const TaskSetup& setup, const std::string& planner_name, PlannerSettings settings,
                        bool disable_sensors, int iterations, double period) {
  PlanningModelSettings ms_settings;
  ms_settings.timestep = settings.dt;
  ms_settings.disable_sensors = disable_sensors;
  if (setup.contact >= 0) ms_settings.contact_margin = ms_settings.contact_softness = setup.contact;
  auto model = loadPlanningModel(setup.planning_file, ms_settings);
  auto sim_model = adroit::loadModelFile(setup.sim_file).model;
  if (sim_model->nq != model->nq || sim_model->nv != model->nv || sim_model->na != model->na)
    throw std::runtime_error(setup.sim_file + ": state sizes differ from the planning model's");
  adroit::DataPtr sim = adroit::makeData(sim_model.get());
  adroit::DataPtr observed = adroit::makeData(model.get());  // the task observes on the planning model
  startTrial(setup.task, sim_model.get(), sim.get());

  auto task = makeTask(setup.task, {});
  task->bind(model.get(), settings.synergies ? Synergies::kCount : 0);  // for error() on the simulation
  auto planner = makePlanner(planner_name);
  planner->initialize(model.get(), *task, settings);
  PlanPolicy policy;
  PlannerState state;
  RunResult result;
  const int object_body = mj_name2id(sim_model.get(), mjOBJ_BODY, "object");
  result.min_object_z = 1e9;
  const int steps = static_cast<int>(std::lround(period / sim_model->opt.timestep));
  for (int i = 0; i < iterations; ++i) {
    state.time = sim->time;
    state.qpos.assign(sim->qpos, sim->qpos + sim_model->nq);
    state.qvel.assign(sim->qvel, sim->qvel + sim_model->nv);
    state.act.assign(sim->act, sim->act + sim_model->na);
    if (i == iterations / 2) giveTaskWork(*task);
    mju_copy(observed->qpos, sim->qpos, model->nq);
    mju_copy(observed->qvel, sim->qvel, model->nv);
    if (model->na) mju_copy(observed->act, sim->act, model->na);
    observed->time = sim->time;
    mj_forward(model.get(), observed.get());
    task->observe(model.get(), observed.get(), sim->time);
    planner->setTask(*task);
    planner->setState(state);
    const double cpu_start = processCpuSeconds();
    OptimizeReport r = planner->optimize();
    const double cpu = processCpuSeconds() - cpu_start;
    if (r.diverged) ++result.diverged;
    if (i > 0) result.series.add(r, cpu);  // the first call warms caches and sizes
    planner->policy(policy);
    for (int k = 0; k < steps; ++k) {
      policy.action(sim->time, sim->qpos, sim->qvel, sim->act, sim->ctrl);
      mj_step(sim_model.get(), sim.get());
    }
    result.min_object_z = std::min(result.min_object_z, sim->xpos[3 * object_body + 2]);
  }
  result.final_error = task->error(sim_model.get(), sim.get());
  return result;
}

// Mean time of one mj_step and one mjd_transitionFD (forward differences) on one core.
void stepAndFdTime(const mjModel* m, double& step_us, double& fd_ms) {
  adroit::DataPtr d = adroit::makeData(m);
  const int rest = mj_name2id(m, mjOBJ_KEY, "rest");
  if (rest >= 0) mj_resetDataKeyframe(m, d.get(), rest);
  for (int i = 0; i < 60; ++i) mj_step(m, d.get());  // bottle on its way down
  adroit::DataPtr probe = adroit::copyData(m, d.get());
  adroit::Stopwatch clock;
  const int n_steps = 500;
  for (int i = 0; i < n_steps; ++i) mj_step(m, probe.get());
  step_us = 1e6 * clock.elapsed() / n_steps;
  const int nx = 2 * m->nv + m->na;
  std::vector<double> A(nx * nx), B(nx * m->nu);
  clock.restart();
  const int n_fd = 20;
  for (int i = 0; i < n_fd; ++i) mjd_transitionFD(m, d.get(), 1e-6, 0, A.data(), B.data(), nullptr, nullptr);
  fd_ms = 1e3 * clock.elapsed() / n_fd;
}

// Mean and max active contacts per step over a falling-bottle rollout at zero tension,
// counted from the first contact of the bottle on.
void contactStats(const mjModel* m, double seconds, double& mean, int& max) {
  adroit::DataPtr d = adroit::makeData(m);
  const int rest = mj_name2id(m, mjOBJ_KEY, "rest");
  if (rest >= 0) mj_resetDataKeyframe(m, d.get(), rest);
  double sum = 0;
  int count = 0;
  max = 0;
  while (d->time < seconds) {
    mj_step(m, d.get());
    const int n = activeContacts(d.get());
    sum += n;
    ++count;
    max = std::max(max, n);
  }
  mean = sum / count;
}

// The planning XML with every spatial tendon replaced by a fixed tendon whose joint
// coefficients are the spatial tendon's moment arms at the rest pose (constant).
std::string fixedTendonXml(const std::string& xml, const mjModel* m) {
  adroit::DataPtr d = adroit::makeData(m);
  const int rest = mj_name2id(m, mjOBJ_KEY, "rest");
  if (rest >= 0) mj_resetDataKeyframe(m, d.get(), rest);
  mj_forward(m, d.get());
  std::regex spatial(R"re(<spatial name="([^"]+)"[^>]*>.*?</spatial>)re");
  std::smatch match;
  std::ostringstream built;
  auto begin = xml.cbegin();
  while (std::regex_search(begin, xml.cend(), match, spatial)) {
    built << std::string(begin, match[0].first);
    const std::string name = match[1];
    const int t = mj_name2id(m, mjOBJ_TENDON, name.c_str());
    built << "<fixed name=\"" << name << "\">";
    std::vector<double> moment(m->nv, 0.0);  // dense row of the tendon Jacobian
    if (mj_isSparse(m)) {
      for (int k = 0; k < d->ten_J_rownnz[t]; ++k)
        moment[d->ten_J_colind[d->ten_J_rowadr[t] + k]] = d->ten_J[d->ten_J_rowadr[t] + k];
    } else {
      for (int v = 0; v < m->nv; ++v) moment[v] = d->ten_J[t * m->nv + v];
    }
    for (int j = 0; j < m->njnt; ++j) {
      if (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE) continue;
      const double arm = moment[m->jnt_dofadr[j]];
      if (std::fabs(arm) > 1e-9)
        built << "<joint joint=\"" << mj_id2name(m, mjOBJ_JOINT, j) << "\" coef=\"" << arm << "\"/>";
    }
    built << "</fixed>";
    begin = match[0].second;
  }
  built << std::string(begin, xml.cend());
  return built.str();
}

// "a,b,c" -> {a, b, c}.
std::vector<std::string> commaList(std::string text) {
  std::replace(text.begin(), text.end(), ',', ' ');
  return adroit::splitWords(text);
}

struct Comparison {
  std::vector<std::string> planners{"ilqg", "sampling", "cem"}, tasks{"catch", "relocate", "type"};
  PlannerSettings base;  // samples and the CEM settings; the tasks' hints go on top
  int iterations = 50;
};

// 2b. Every planner on every task with the task's planner hints. Returns the median wall
// time per iteration by "task/planner", ms.
std::map<std::string, double> comparePlanners(const std::string& share, const Comparison& c, double period) {
  std::printf("\nPlanners per task (%d iterations each, control period %.0f ms; sampling planners: %d samples, "
              "CEM %d elites, std %.3g down to %.3g of the range)\n", c.iterations, 1e3 * period, c.base.samples,
              c.base.cem_elites, c.base.cem_std_initial, c.base.cem_std_min);
  std::printf("%-9s %-9s %6s %7s %10s %10s %10s %9s %9s %10s\n", "task", "planner", "dt", "knots", "median", "p90",
              "CPU med.", "CPU/iLQG", "diverged", "final err");
  std::map<std::string, double> medians;
  for (const std::string& task : c.tasks) {
    const TaskSetup setup = taskSetup(share, task);
    const PlannerSettings settings = taskSettings(task, c.base);
    double ilqg_cpu = 0;
    for (const std::string& planner : c.planners) {
      RunResult r = runClosedLoop(setup, planner, settings, true, c.iterations, period);
      const double cpu = ms(r.series.cpu, 50);
      if (planner == "ilqg") ilqg_cpu = cpu;
      medians[task + "/" + planner] = ms(r.series.total, 50);
      char ratio[16] = "-";
      if (ilqg_cpu > 0) std::snprintf(ratio, sizeof ratio, "%.2f", cpu / ilqg_cpu);
      std::printf("%-9s %-9s %6.3f %7ld %10.2f %10.2f %10.2f %9s %9d %10.4f\n", task.c_str(), planner.c_str(),
                  settings.dt, std::lround(settings.horizon / settings.dt), ms(r.series.total, 50),
                  ms(r.series.total, 90), cpu, ratio, r.diverged, r.final_error);
    }
  }
  return medians;
}

void printCpuRatio(double before, double shipped) {
  const double ratio = shipped / before;
  std::printf("RESULT adroit_mpc/ilqg_cpu_per_iteration_ratio %.2f ratio target <= 0.5 %s\n", ratio,
              ratio <= 0.5 ? "PASS" : "FAIL");
}

// 2a. The derivative path before issue 38 (every knot of the skip pattern at every call, one
// nudge per control) against the shipped one (derivatives reused across calls, B through the
// generalised forces), on the same closed loop in alternating blocks (ABBA: the order swaps
// every block), so that a change of the machine's load falls on both. Returns the median CPU
// time per iteration of each, ms.
std::pair<double, double> compareDerivativePaths(const TaskSetup& setup, const PlannerSettings& shipped,
                                                 int iterations, int blocks, double period) {
  PlannerSettings before = shipped;
  before.derivative_max_age = 0;
  before.fd_force_space = false;
  std::array<Series, 2> series;  // before, shipped
  std::array<std::vector<double>, 2> errors;
  std::array<int, 2> diverged{0, 0};
  for (int b = 0; b < blocks; ++b) {
    for (int k = 0; k < 2; ++k) {
      const int path = b % 2 == 0 ? k : 1 - k;
      const RunResult r = runClosedLoop(setup, "ilqg", path ? shipped : before, true, iterations, period);
      Series& s = series[path];
      append(s.rollout, r.series.rollout);
      append(s.derivatives, r.series.derivatives);
      append(s.cost, r.series.cost);
      append(s.backward, r.series.backward);
      append(s.line_search, r.series.line_search);
      append(s.total, r.series.total);
      append(s.cpu, r.series.cpu);
      append(s.knots, r.series.knots);
      errors[path].push_back(r.final_error);
      diverged[path] += r.diverged;
    }
  }
  std::printf("\niLQG derivative paths, paired (%s, %d blocks x %d iterations each, alternating ABBA; derivative "
              "max age %.3g s, reuse tolerance %.3g, B through the generalised forces %s)\n",
              setup.task.c_str(), blocks, iterations, shipped.derivative_max_age, shipped.derivative_reuse_tolerance,
              shipped.fd_force_space ? "on" : "off");
  std::printf("%-34s %10s %10s %10s %10s %12s %10s %9s %10s\n", "path", "wall med.", "wall p90", "CPU med.", "CPU p90",
              "deriv. med.", "FD knots", "diverged", "final err");
  const char* names[2] = {"before (every knot, per control)", "shipped (reuse, force space)"};
  for (int path = 0; path < 2; ++path) {
    const Series& s = series[path];
    std::printf("%-34s %10.2f %10.2f %10.2f %10.2f %12.2f %10.2f %9d %10.4f\n", names[path], ms(s.total, 50),
                ms(s.total, 90), ms(s.cpu, 50), ms(s.cpu, 90), ms(s.derivatives, 50), mean(s.knots), diverged[path],
                mean(errors[path]));
  }
  return {ms(series[0].cpu, 50), ms(series[1].cpu, 50)};
}

}  // namespace

int main(int argc, char** argv) {
  int iterations = 50, blocks = 4;
  bool quick = false, compare_only = false, paths_only = false;
  // Defaults as shipped: the catch task's planner_dt (config/tasks/catch.yaml) and
  // derivative_skip of config/mpc.yaml.
  double dt = paramNumber("catch", defaultTaskParams("catch"), "planner_dt", 1e-4, 0.1);
  int skip = PlannerSettings().derivative_skip;
  double max_age = PlannerSettings().derivative_max_age, reuse_tolerance = PlannerSettings().derivative_reuse_tolerance;
  Comparison comparison;
  adroit::CommandLine args(argc, argv,
                           "usage: mpc_timing [--iterations N] [--dt S] [--skip K] [--quick] [--compare-only] "
                           "[--paths-only] [--blocks N] [--max-age S] [--reuse-tolerance X] [--planners ilqg,sampling,cem] "
                           "[--tasks catch,relocate,type] [--samples N] [--cem-elites N] [--cem-std-initial S] [--cem-std-min S]");
  while (args.next()) {
    if (args.is("--iterations")) iterations = static_cast<int>(args.integer());
    else if (args.is("--dt")) dt = args.number();
    else if (args.is("--skip")) skip = static_cast<int>(args.integer());
    else if (args.is("--quick")) quick = true;
    else if (args.is("--compare-only")) compare_only = true;
    else if (args.is("--paths-only")) paths_only = true;
    else if (args.is("--blocks")) blocks = static_cast<int>(args.integer());
    else if (args.is("--max-age")) max_age = args.number();
    else if (args.is("--reuse-tolerance")) reuse_tolerance = args.number();
    else if (args.is("--planners")) comparison.planners = commaList(args.text());
    else if (args.is("--tasks")) comparison.tasks = commaList(args.text());
    else if (args.is("--samples")) comparison.base.samples = static_cast<int>(args.integer());
    else if (args.is("--cem-elites")) comparison.base.cem_elites = static_cast<int>(args.integer());
    else if (args.is("--cem-std-initial")) comparison.base.cem_std_initial = args.number();
    else if (args.is("--cem-std-min")) comparison.base.cem_std_min = args.number();
    else args.unknown();
  }
  if (blocks < 1) args.fail("--blocks must be at least 1");
  comparison.iterations = iterations;
  try {
    if (compare_only) {
      double load[1] = {0};
      if (getloadavg(load, 1) < 1) load[0] = -1;
      std::printf("MPC planners per task, %u cores, load average %.1f\n",
                  std::max(1u, std::thread::hardware_concurrency()), load[0]);
      comparePlanners(descriptionShareDir(), comparison, 0.02);
      return 0;
    }
    // The shipped settings on the catch (config/mpc.yaml, config/tasks/catch.yaml).
    PlannerSettings chosen;
    chosen.horizon = 0.3;
    chosen.dt = dt;
    chosen.threads = 0;
    chosen.synergies = true;
    chosen.derivative_skip = skip;
    chosen.derivative_max_age = max_age;
    chosen.derivative_reuse_tolerance = reuse_tolerance;
    chosen.samples = 16;
    const double period = 0.02;
    if (paths_only) {
      double load[1] = {0};
      if (getloadavg(load, 1) < 1) load[0] = -1;
      std::printf("MPC derivative paths, catch, %u cores, load average %.1f\n",
                  std::max(1u, std::thread::hardware_concurrency()), load[0]);
      const auto [before, shipped] =
          compareDerivativePaths(taskSetup(descriptionShareDir(), "catch"), chosen, iterations, blocks, period);
      printCpuRatio(before, shipped);
      return 0;
    }
    Scene scene;
    scene.share = descriptionShareDir();
    scene.planning_file = adroit::description::sceneFile(scene.share, "bottle", true);
    scene.sim_file = adroit::description::sceneFile(scene.share, "bottle", false);
    const TaskSetup catch_setup = taskSetup(scene.share, "catch");
    const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
    double load[1] = {0};
    if (getloadavg(load, 1) < 1) load[0] = -1;
    std::printf("MPC timing, bottle catch scene, %u cores, horizon 0.3 s, load average %.1f%s\n\n", cores, load[0],
                load[0] > 0.5 ? " (NOT idle: wall times are inflated, see the CPU rows)" : "");

    // 1. Step and FD knot cost.
    std::printf("Planning model cost per knot (one core)\n");
    std::printf("%-44s %10s %12s\n", "model", "step [us]", "FD knot [ms]");
    for (double knot_dt : {0.002, 0.005, 0.01, 0.02}) {
      for (bool off : {false, true}) {
        PlanningModelSettings s;
        s.timestep = knot_dt;
        s.disable_sensors = off;
        auto m = loadPlanningModel(scene.planning_file, s);
        double step_us, fd_ms;
        stepAndFdTime(m.get(), step_us, fd_ms);
        char label[64];
        std::snprintf(label, sizeof label, "dt %.3f s, sensors %s, smooth contacts", knot_dt, off ? "off" : "on");
        std::printf("%-44s %10.1f %12.2f\n", label, step_us, fd_ms);
      }
    }
    {
      PlanningModelSettings s;
      s.timestep = 0.01;
      s.solver_iterations = 5;
      auto m = loadPlanningModel(scene.planning_file, s);
      double step_us, fd_ms;
      stepAndFdTime(m.get(), step_us, fd_ms);
      std::printf("%-44s %10.1f %12.2f\n", "dt 0.010 s, sensors off, 5 solver iterations", step_us, fd_ms);
    }
    PlanningModelSettings base_settings;
    base_settings.timestep = 0.005;
    auto base = loadPlanningModel(scene.planning_file, base_settings);
    auto fixed = adroit::loadModelString(fixedTendonXml(readModelText(scene.planning_file), base.get())).model;
    applyPlanningSettings(fixed.get(), base_settings);
    double fixed_step_us, fixed_fd_ms;
    stepAndFdTime(fixed.get(), fixed_step_us, fixed_fd_ms);
    std::printf("%-44s %10.1f %12.2f\n", "dt 0.005 s, sensors off, FIXED tendons (what-if)", fixed_step_us, fixed_fd_ms);

    // 1b. Grouped finite differences (fd_derivatives.h) against MuJoCo's one column per DOF,
    // paired in alternating blocks on the same knots: the keypad at rest with the typing
    // task's contact settings (twelve keys, one tree each), the bottle falling free.
    std::printf("\nFinite differences per knot, one core: mjd_transitionFD against trees nudged together\n");
    std::printf("%-34s %8s %8s %12s %12s %7s %10s\n", "knot", "nv", "columns", "mjd [ms]", "grouped [ms]", "ratio",
                "max |dA|");
    for (const char* which : {"keypad", "bottle"}) {
      const bool keypad = std::string(which) == "keypad";
      PlanningModelSettings s;
      s.timestep = 0.01;
      if (keypad) s.contact_margin = s.contact_softness = 0.001;  // config/tasks/type.yaml's node settings
      auto m = loadPlanningModel(adroit::description::sceneFile(scene.share, which, true), s);
      adroit::DataPtr d = adroit::makeData(m.get());
      const int rest = mj_name2id(m.get(), mjOBJ_KEY, "rest");
      if (rest >= 0) mj_resetDataKeyframe(m.get(), d.get(), rest);
      const int object = mj_name2id(m.get(), mjOBJ_BODY, "object");
      if (!keypad && object >= 0) d->qpos[m->jnt_qposadr[m->body_jntadr[object]] + 2] += 0.15;  // above the palm
      for (int a = 0; a < m->nu; ++a) d->ctrl[a] = m->actuator_ctrlrange[2 * a];
      mj_forward(m.get(), d.get());
      const int nx = 2 * m->nv + m->na;
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> A_ref(nx, nx), B_ref(nx, m->nu);
      Eigen::MatrixXd A(nx, nx), B(nx, m->nu);
      FdDerivatives fd;
      fd.initialize(m.get(), 1, 1, FdSettings{1e-6, false, 1, true});
      adroit::DataPtr work = adroit::makeData(m.get());
      std::vector<double> mjd_ms, grouped_ms;
      int columns = 0;
      for (int block = 0; block < 10; ++block) {
        adroit::Stopwatch clock;
        for (int k = 0; k < 5; ++k) {
          mj_copyData(work.get(), m.get(), d.get());
          mjd_transitionFD(m.get(), work.get(), 1e-6, 0, A_ref.data(), B_ref.data(), nullptr, nullptr);
        }
        mjd_ms.push_back(1e3 * clock.elapsed() / 5);
        clock.restart();
        for (int k = 0; k < 5; ++k) {
          mj_copyData(work.get(), m.get(), d.get());
          columns = fd.knot(work.get(), 0, A, B);
        }
        grouped_ms.push_back(1e3 * clock.elapsed() / 5);
      }
      const double a = adroit::percentile(mjd_ms, 50), b = adroit::percentile(grouped_ms, 50);
      char label[64];
      std::snprintf(label, sizeof label, "%s (%d contacts)", keypad ? "keypad at rest" : "bottle falling", d->ncon);
      std::printf("%-34s %8d %8d %12.2f %12.2f %7.2f %10.1e\n", label, m->nv, columns, a, b, b / a,
                  (A - Eigen::MatrixXd(A_ref)).cwiseAbs().maxCoeff());
    }

    // 1c. Explicit contact pairs (planning_model.h, the default) against MuJoCo's dynamic
    // collisions on the same knots, alternating blocks: one step, and one grouped FD knot.
    std::printf("\nCollision by explicit pairs (the default) against MuJoCo's dynamic collisions, same knots\n");
    std::printf("%-34s %7s %11s %11s %7s %11s %11s %7s\n", "knot", "pairs", "step dyn", "step pairs", "ratio",
                "FD dyn", "FD pairs", "ratio");
    // The knot's state into the working data, as a rollout sets it (a full mj_copyData would
    // cost more than the step).
    const auto setKnot = [](const mjModel* m, const mjData* from, mjData* to) {
      mju_copy(to->qpos, from->qpos, m->nq);
      mju_copy(to->qvel, from->qvel, m->nv);
      mju_copy(to->act, from->act, m->na);
      mju_copy(to->ctrl, from->ctrl, m->nu);
      mju_zero(to->qacc_warmstart, m->nv);
      to->time = from->time;
    };
    for (const char* which : {"keypad", "bottle"}) {
      const bool keypad = std::string(which) == "keypad";
      std::array<adroit::ModelPtr, 2> models;  // dynamic, explicit pairs
      std::array<adroit::DataPtr, 2> knots, work;
      std::array<FdDerivatives, 2> fds;
      for (int k = 0; k < 2; ++k) {
        PlanningModelSettings s;
        s.timestep = 0.01;
        if (keypad) s.contact_margin = s.contact_softness = 0.001;
        s.explicit_pairs = k == 1;
        models[k] = loadPlanningModel(adroit::description::sceneFile(scene.share, which, true), s);
        const mjModel* m = models[k].get();
        knots[k] = adroit::makeData(m);
        work[k] = adroit::makeData(m);
        mj_resetDataKeyframe(m, knots[k].get(), mj_name2id(m, mjOBJ_KEY, "rest"));
        const int object = mj_name2id(m, mjOBJ_BODY, "object");
        if (object >= 0) knots[k]->qpos[m->jnt_qposadr[m->body_jntadr[object]] + 2] += 0.15;  // above the palm
        for (int a = 0; a < m->nu; ++a) knots[k]->ctrl[a] = m->actuator_ctrlrange[2 * a];
        mj_forward(m, knots[k].get());
        fds[k].initialize(m, 1, 1, FdSettings{1e-6, false, 1, true});
      }
      const int nx = 2 * models[0]->nv + models[0]->na;
      Eigen::MatrixXd A(nx, nx), B(nx, models[0]->nu);
      std::array<std::vector<double>, 2> step_us, fd_ms;
      for (int block = 0; block < 10; ++block) {
        for (int k = 0; k < 2; ++k) {
          const mjModel* m = models[k].get();
          adroit::Stopwatch clock;
          for (int i = 0; i < 100; ++i) {
            setKnot(m, knots[k].get(), work[k].get());
            mj_step(m, work[k].get());
          }
          step_us[k].push_back(1e6 * clock.elapsed() / 100);
          clock.restart();
          for (int i = 0; i < 5; ++i) {
            setKnot(m, knots[k].get(), work[k].get());
            fds[k].knot(work[k].get(), 0, A, B);
          }
          fd_ms[k].push_back(1e3 * clock.elapsed() / 5);
        }
      }
      const double s0 = adroit::percentile(step_us[0], 50), s1 = adroit::percentile(step_us[1], 50);
      const double f0 = adroit::percentile(fd_ms[0], 50), f1 = adroit::percentile(fd_ms[1], 50);
      std::printf("%-34s %7d %9.1f us %9.1f us %7.2f %8.2f ms %8.2f ms %7.2f\n",
                  keypad ? "keypad at rest (typing contacts)" : "bottle falling", models[1]->npair, s0, s1, s1 / s0, f0,
                  f1, f1 / f0);
    }

    // 2. Closed loop, chosen defaults (config/mpc.yaml).
    std::printf("\niLQG closed loop (%d iterations, control period %.0f ms, dt %.3f, skip %d, synergies)\n",
                iterations, 1e3 * period, chosen.dt, chosen.derivative_skip);
    RunResult ilqg = runClosedLoop(catch_setup, "ilqg", chosen, true, iterations, period);
    RunResult sampling = runClosedLoop(catch_setup, "sampling", chosen, true, iterations, period);
    std::printf("%-22s %10s %10s   %s\n", "phase [ms]", "median", "p90", "thesis table 6.2 (6 cores)");
    const Series& s = ilqg.series;
    std::printf("%-22s %10.2f %10.2f   %s\n", "rollout", ms(s.rollout, 50), ms(s.rollout, 90), "6");
    std::printf("%-22s %10.2f %10.2f   %s\n", "derivatives", ms(s.derivatives, 50), ms(s.derivatives, 90), "36");
    std::printf("%-22s %10.2f %10.2f   %s\n", "cost", ms(s.cost, 50), ms(s.cost, 90), "1");
    std::printf("%-22s %10.2f %10.2f   %s\n", "backward pass", ms(s.backward, 50), ms(s.backward, 90), "10");
    std::printf("%-22s %10.2f %10.2f   %s\n", "line search", ms(s.line_search, 50), ms(s.line_search, 90), "7");
    std::printf("%-22s %10.2f %10.2f   %s\n", "total iLQG", ms(s.total, 50), ms(s.total, 90), "59");
    std::printf("%-22s %10.2f %10.2f   (CPU time of all threads)\n", "CPU iLQG", ms(s.cpu, 50), ms(s.cpu, 90));
    std::printf("%-22s %10.2f %10s   (mean; the rest held or reused)\n", "FD knots evaluated", mean(s.knots), "");
    std::printf("%-22s %10.2f %10.2f   (%d samples)\n", "total pred. sampling", ms(sampling.series.total, 50),
                ms(sampling.series.total, 90), chosen.samples);
    std::printf("%-22s %10.2f %10.2f\n", "CPU pred. sampling", ms(sampling.series.cpu, 50), ms(sampling.series.cpu, 90));
    std::printf("diverged iterations: iLQG %d, sampling %d; object distance to goal at the end: iLQG %.3f m, "
                "sampling %.3f m\n", ilqg.diverged, sampling.diverged, ilqg.final_error, sampling.final_error);

    // 2a. The derivative path before and after issue 38, paired.
    const auto [cpu_before, cpu_shipped] = compareDerivativePaths(catch_setup, chosen, iterations, blocks, period);

    // 2b. The planners side by side on every task.
    const std::map<std::string, double> per_task = comparePlanners(scene.share, comparison, period);

    // 3. Design choices.
    if (!quick) {
      std::printf("\niLQG total per iteration by setting (median / p90 ms, 15 iterations each)\n");
      std::printf("%-8s %-6s %-8s %-9s %10s %10s %10s\n", "dt", "skip", "threads", "sensors", "median", "p90", "CPU med.");
      struct Choice { double dt; int skip; int threads; bool sensors_off; };
      const Choice choices[] = {{0.005, 1, 0, false}, {0.005, 1, 0, true}, {0.005, 4, 0, true}, {0.005, 6, 0, true},
                                {0.01, 1, 0, true},    {0.01, 2, 0, false}, {0.01, 2, 1, true}, {0.01, 2, 0, true},
                                {0.01, 3, 0, true},    {0.02, 1, 0, true},  {0.02, 2, 0, true},  {0.02, 3, 0, true}};
      for (const Choice& c : choices) {
        PlannerSettings p = chosen;
        p.dt = c.dt;
        p.derivative_skip = c.skip;
        p.threads = c.threads;
        RunResult r = runClosedLoop(catch_setup, "ilqg", p, c.sensors_off, 16, period);
        std::printf("%-8.3f %-6d %-8d %-9s %10.2f %10.2f %10.2f\n", c.dt, c.skip,
                    c.threads ? c.threads : static_cast<int>(cores), c.sensors_off ? "off" : "on",
                    ms(r.series.total, 50), ms(r.series.total, 90), ms(r.series.cpu, 50));
      }
    }

    // 4. Contact pruning.
    PlanningModelSettings contact_settings;
    auto pruned = loadPlanningModel(scene.planning_file, contact_settings);
    auto unpruned = loadUnprunedPlanningModel(scene.planning_file, contact_settings);
    double mean_pruned, mean_unpruned, step_pruned, step_unpruned, fd_unused;
    int max_pruned, max_unpruned;
    contactStats(pruned.get(), 1.0, mean_pruned, max_pruned);
    contactStats(unpruned.get(), 1.0, mean_unpruned, max_unpruned);
    stepAndFdTime(pruned.get(), step_pruned, fd_unused);
    stepAndFdTime(unpruned.get(), step_unpruned, fd_unused);
    std::printf("\nActive contacts per step, falling bottle, 1 s, zero tension (thesis 6.4.3: 40 -> 20)\n");
    std::printf("%-12s %8s %6s %10s\n", "model", "mean", "max", "step [us]");
    std::printf("%-12s %8.1f %6d %10.1f\n", "unpruned", mean_unpruned, max_unpruned, step_unpruned);
    std::printf("%-12s %8.1f %6d %10.1f\n", "pruned", mean_pruned, max_pruned, step_pruned);

    const double median = ms(ilqg.series.total, 50);
    std::printf("\nRESULT adroit_mpc/ilqg_iteration_ms %.1f ms target <= 50 %s\n", median, median <= 50 ? "PASS" : "FAIL");
    std::printf("RESULT adroit_mpc/sampling_iteration_ms %.1f ms target <= 50 %s\n", ms(sampling.series.total, 50),
                ms(sampling.series.total, 50) <= 50 ? "PASS" : "FAIL");
    if (per_task.count("catch/cem")) {
      const double cem = per_task.at("catch/cem");
      std::printf("RESULT adroit_mpc/cem_iteration_ms %.1f ms target <= 50 %s\n", cem, cem <= 50 ? "PASS" : "FAIL");
    }
    std::printf("RESULT adroit_mpc/active_contacts_pruned_ratio %.2f ratio target <= 0.7 %s\n",
                mean_pruned / mean_unpruned, mean_pruned / mean_unpruned <= 0.7 ? "PASS" : "FAIL");
    printCpuRatio(cpu_before, cpu_shipped);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mpc_timing: %s\n", e.what());
    return 1;
  }
  return 0;
}
