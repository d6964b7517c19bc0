#include "adroit_mpc/fd_derivatives.h"

#include "adroit_mpc/planner.h"  // integrateAfterForward

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

namespace adroit_mpc {

namespace {

// Union-find over trees, indexed by their top moving body (0 = the world and everything
// welded to it, never merged).
int findGroup(std::vector<int>& group, int tree) {
  while (group[tree] != tree) tree = group[tree] = group[group[tree]];
  return tree;
}

void unite(std::vector<int>& group, int tree_a, int tree_b) {
  if (tree_a == 0 || tree_b == 0) return;  // the world is fixed: touching it couples nothing
  const int a = findGroup(group, tree_a), b = findGroup(group, tree_b);
  if (a != b) group[std::max(a, b)] = std::min(a, b);
}

// The tree of a body: its highest ancestor that moves (whose parent is welded to the world),
// 0 for static bodies. Keys on a fixed keypad are trees of their own.
int movingTree(const mjModel* m, int body) {
  if (m->body_weldid[body] == 0) return 0;
  while (m->body_weldid[m->body_parentid[body]] != 0) body = m->body_parentid[body];
  return body;
}

// The tree of a tendon's first body, or -1 when it wraps nothing of a body.
int tendonTree(const mjModel* m, int tendon, std::vector<int>& group) {
  int first = -1;
  for (int w = m->tendon_adr[tendon]; w < m->tendon_adr[tendon] + m->tendon_num[tendon]; ++w) {
    const int obj = m->wrap_objid[w];
    int body = -1;
    switch (m->wrap_type[w]) {
      case mjWRAP_JOINT: body = m->jnt_bodyid[obj]; break;
      case mjWRAP_SITE: body = m->site_bodyid[obj]; break;
      case mjWRAP_SPHERE:
      case mjWRAP_CYLINDER: body = m->geom_bodyid[obj]; break;
      default: break;  // pulley
    }
    if (body < 0) continue;
    const int tree = movingTree(m, body);
    if (first < 0) first = tree;
    else unite(group, first, tree);  // a tendon couples every tree it spans
  }
  return first;
}

}  // namespace

void setKnotState(const mjModel* m, mjData* d, const Eigen::VectorXd& state, const Eigen::VectorXd& ctrl,
                  double time) {
  mju_copy(d->qpos, state.data(), m->nq);
  mju_copy(d->qvel, state.data() + m->nq, m->nv);
  if (m->na) mju_copy(d->act, state.data() + m->nq + m->nv, m->na);
  mju_copy(d->ctrl, ctrl.data(), m->nu);
  mju_zero(d->qacc_warmstart, m->nv);  // cold, as in rollout(): independent of the worker's history
  d->time = time;
}

void FdDerivatives::initialize(const mjModel* m, int horizon, int workers, const FdSettings& settings) {
  if (!(settings.epsilon > 0)) throw std::invalid_argument("fd derivatives: epsilon must be positive");
  if (settings.skip < 1) throw std::invalid_argument("fd derivatives: derivative_skip must be >= 1, got " +
                                                      std::to_string(settings.skip));
  if (horizon < 1) throw std::invalid_argument("fd derivatives: horizon must be >= 1 knot");
  if (workers < 1) throw std::invalid_argument("fd derivatives: need at least one worker");
  if (m->opt.integrator == mjINT_RK4) throw std::invalid_argument("fd derivatives: the RK4 integrator is not supported");
  if (!(settings.max_age >= 0) || !std::isfinite(settings.max_age))
    throw std::invalid_argument("fd derivatives: max_age must be >= 0 and finite, got " + std::to_string(settings.max_age));
  if (!(settings.reuse_tolerance > 0) || !std::isfinite(settings.reuse_tolerance))
    throw std::invalid_argument("fd derivatives: reuse_tolerance must be positive and finite");
  model_ = m;
  settings_ = settings;
  horizon_ = horizon;
  nx_ = 2 * m->nv + m->na;
  computed_.clear();
  for (int t = 0; t < horizon; t += settings.skip) computed_.push_back(t);
  if (computed_.back() != horizon - 1) computed_.push_back(horizon - 1);

  body_tree_.resize(m->nbody);
  for (int b = 0; b < m->nbody; ++b) body_tree_[b] = movingTree(m, b);
  dof_tree_.resize(m->nv);
  for (int i = 0; i < m->nv; ++i) dof_tree_[i] = body_tree_[m->dof_bodyid[i]];
  // Trees coupled whatever the state: by a tendon, a two-site actuator, an equality.
  static_group_.resize(m->nbody);
  std::iota(static_group_.begin(), static_group_.end(), 0);
  std::vector<int>& g = static_group_;
  std::vector<int> tendon_tree(m->ntendon);
  for (int t = 0; t < m->ntendon; ++t) tendon_tree[t] = tendonTree(m, t, g);
  for (int a = 0; a < m->nu; ++a)
    if (m->actuator_trntype[a] == mjTRN_SLIDERCRANK)
      unite(g, body_tree_[m->site_bodyid[m->actuator_trnid[2 * a]]],
            body_tree_[m->site_bodyid[m->actuator_trnid[2 * a + 1]]]);
  bool couple_all = !settings.group_trees || m->na > 0;  // activations: keep it simple, no grouping
  for (int e = 0; e < m->neq && !couple_all; ++e) {
    const int o1 = m->eq_obj1id[e], o2 = m->eq_obj2id[e];
    switch (m->eq_type[e]) {
      case mjEQ_CONNECT:
      case mjEQ_WELD:
        unite(g, body_tree_[o1], body_tree_[o2]);
        break;
      case mjEQ_JOINT:
        if (o2 >= 0) unite(g, body_tree_[m->jnt_bodyid[o1]], body_tree_[m->jnt_bodyid[o2]]);
        break;
      case mjEQ_TENDON:
        if (o2 >= 0 && tendon_tree[o1] >= 0 && tendon_tree[o2] >= 0) unite(g, tendon_tree[o1], tendon_tree[o2]);
        break;
      default:
        couple_all = true;  // a constraint this code does not know: no grouping
    }
  }
  if (couple_all)
    for (int i = 1; i < m->nv; ++i) unite(g, dof_tree_[0], dof_tree_[i]);

  pair_of_geoms_.clear();
  if (m->opt.collision == mjCOL_PAIR) {
    for (int p = 0; p < m->npair; ++p) {
      const long low = std::min(m->pair_geom1[p], m->pair_geom2[p]), high = std::max(m->pair_geom1[p], m->pair_geom2[p]);
      pair_of_geoms_.emplace_back(low * m->ngeom + high, p);
    }
    std::sort(pair_of_geoms_.begin(), pair_of_geoms_.end());
  }

  linear_actuator_.assign(m->nu, 0);
  for (int a = 0; a < m->nu; ++a)
    linear_actuator_[a] = m->actuator_dyntype[a] == mjDYN_NONE && m->actuator_gaintype[a] == mjGAIN_FIXED &&
                          (m->actuator_biastype[a] == mjBIAS_NONE || m->actuator_biastype[a] == mjBIAS_AFFINE);

  data_.clear();
  scratch_.clear();
  scratch_.resize(workers);
  const int n_state = m->nq + m->nv + m->na;
  for (int w = 0; w < workers; ++w) {
    data_.push_back(adroit::makeData(m));
    Scratch& s = scratch_[w];
    s.qpos.resize(m->nq);
    s.qvel.resize(m->nv);
    s.act.resize(m->na);
    s.ctrl.resize(m->nu);
    s.warmstart.resize(m->nv);
    s.next.resize(n_state);
    s.plus.resize(n_state);
    s.minus.resize(n_state);
    s.dpos.resize(m->nv);
    s.delta.resize(nx_);
    s.group.resize(m->nbody);
    s.slot.resize(m->nv);
    s.count.resize(m->nbody);
    s.representative.resize(m->nv);
    if (!pair_of_geoms_.empty()) {
      s.active_pairs.reserve(m->npair);
      s.nudge_model = adroit::copyModel(m);
    }
    s.forced_dofs.reserve(m->nv);
    s.force_columns = Eigen::MatrixXd::Zero(nx_, m->nv);
  }

  const std::size_t n = computed_.size();
  for (auto* kept : {&kept_, &next_}) {
    kept->assign(n, Linearisation{});
    for (Linearisation& k : *kept) {
      k.state = Eigen::VectorXd::Zero(n_state);
      k.A = Eigen::MatrixXd::Zero(nx_, nx_);
      k.B = Eigen::MatrixXd::Zero(nx_, m->nu);
    }
  }
  source_.assign(n, -1);
  evaluate_.clear();
  evaluate_.reserve(n);
  forget();
  dq_ = Eigen::VectorXd::Zero(m->nv);
  x_at_ = Eigen::VectorXd::Zero(n_state);
}

void FdDerivatives::forget() {
  for (Linearisation& k : kept_) k.valid = false;
  kept_t0_valid_ = false;
  refreshes_due_ = 0;
}

void FdDerivatives::save(const mjData* d, Scratch& s) const {
  const mjModel* m = model_;
  mju_copy(s.qpos.data(), d->qpos, m->nq);
  mju_copy(s.qvel.data(), d->qvel, m->nv);
  if (m->na) mju_copy(s.act.data(), d->act, m->na);
  mju_copy(s.ctrl.data(), d->ctrl, m->nu);
  mju_copy(s.warmstart.data(), d->qacc_warmstart, m->nv);
  s.time = d->time;
}

void FdDerivatives::restore(mjData* d, const Scratch& s) const {
  const mjModel* m = model_;
  mju_copy(d->qpos, s.qpos.data(), m->nq);
  mju_copy(d->qvel, s.qvel.data(), m->nv);
  if (m->na) mju_copy(d->act, s.act.data(), m->na);
  mju_copy(d->ctrl, s.ctrl.data(), m->nu);
  mju_copy(d->qacc_warmstart, s.warmstart.data(), m->nv);
  d->time = s.time;
}

void FdDerivatives::stepSkip(const mjModel* m, mjData* d, int skipstage, std::vector<mjtNum>& out) const {
  mj_forwardSkip(m, d, skipstage, 1);
  integrateAfterForward(m, d);
  mju_copy(out.data(), d->qpos, m->nq);
  mju_copy(out.data() + m->nq, d->qvel, m->nv);
  if (m->na) mju_copy(out.data() + m->nq + m->nv, d->act, m->na);
}

void FdDerivatives::nudgedStep(mjData* d, const Scratch& s, mjtNum* input, double by, int skipstage,
                               std::vector<mjtNum>& out) const {
  *input += by;
  stepSkip(model_, d, skipstage, out);
  restore(d, s);  // the input too
}

const mjModel* FdDerivatives::restrictPairs(const mjData* d, Scratch& s) const {
  if (!s.nudge_model) return model_;
  const mjModel* m = model_;
  s.active_pairs.clear();
  for (int c = 0; c < d->ncon; ++c) {
    const long g1 = d->contact[c].geom1, g2 = d->contact[c].geom2;
    const long key = std::min(g1, g2) * m->ngeom + std::max(g1, g2);
    const auto found = std::lower_bound(pair_of_geoms_.begin(), pair_of_geoms_.end(), std::make_pair(key, -1));
    if (found == pair_of_geoms_.end() || found->first != key) return model_;  // not a pair's contact: test them all
    // A pair's contacts are consecutive: each pair once, at most npair (reserved).
    if (s.active_pairs.empty() || s.active_pairs.back() != found->second) s.active_pairs.push_back(found->second);
  }
  // In the model's order (so the contacts keep theirs).
  std::sort(s.active_pairs.begin(), s.active_pairs.end());
  mjModel* n = s.nudge_model.get();
  for (std::size_t k = 0; k < s.active_pairs.size(); ++k) {
    const int p = s.active_pairs[k];
    n->pair_dim[k] = m->pair_dim[p];
    n->pair_geom1[k] = m->pair_geom1[p];
    n->pair_geom2[k] = m->pair_geom2[p];
    n->pair_signature[k] = m->pair_signature[p];
    mju_copy(n->pair_solref + mjNREF * k, m->pair_solref + mjNREF * p, mjNREF);
    mju_copy(n->pair_solimp + mjNIMP * k, m->pair_solimp + mjNIMP * p, mjNIMP);
    n->pair_margin[k] = m->pair_margin[p];
    n->pair_gap[k] = m->pair_gap[p];
    mju_copy(n->pair_friction + 5 * k, m->pair_friction + 5 * p, 5);
  }
  n->npair = static_cast<int>(s.active_pairs.size());
  return n;
}

int FdDerivatives::groupDofs(const mjData* d, Scratch& s) const {
  const mjModel* m = model_;
  std::copy(static_group_.begin(), static_group_.end(), s.group.begin());
  for (int c = 0; c < d->ncon; ++c)  // every contact the nominal step generated couples its two trees
    unite(s.group, body_tree_[m->geom_bodyid[d->contact[c].geom1]], body_tree_[m->geom_bodyid[d->contact[c].geom2]]);
  std::fill(s.count.begin(), s.count.end(), 0);
  int columns = 0;
  for (int i = 0; i < m->nv; ++i) {
    s.representative[i] = findGroup(s.group, dof_tree_[i]);
    s.slot[i] = s.count[s.representative[i]]++;
    columns = std::max(columns, s.slot[i] + 1);
  }
  return columns;
}

void FdDerivatives::difference(const std::vector<mjtNum>& minus, const std::vector<mjtNum>& plus, double h,
                               Scratch& s) const {
  const mjModel* m = model_;
  mj_differentiatePos(m, s.delta.data(), h, minus.data(), plus.data());
  for (int k = 0; k < m->nv + m->na; ++k) s.delta[m->nv + k] = (plus[m->nq + k] - minus[m->nq + k]) / h;
}

int FdDerivatives::knot(mjData* d, std::size_t worker, Eigen::MatrixXd& A, Eigen::MatrixXd& B) {
  const mjModel* m = model_;
  Scratch& s = scratch_[worker];
  const double eps = settings_.epsilon;
  const bool centered = settings_.centered;
  const int nv = m->nv, na = m->na;
  save(d, s);
  stepSkip(m, d, mjSTAGE_NONE, s.next);
  const int columns = groupDofs(d, s);  // from the nominal step's contacts
  const mjModel* position_model = restrictPairs(d, s);
  if (settings_.warmstart_from_nominal && d->nefc > 0) {
    // The nominal step's solution (qacc: the integrator leaves it); the nominal again from
    // there, so that it and every nudge are solved from the same start.
    mju_copy(s.warmstart.data(), d->qacc, nv);
    restore(d, s);
    stepSkip(m, d, mjSTAGE_NONE, s.next);
  }
  restore(d, s);

  // Controls first, while d holds the nominal step's actuator moments and lengths.
  const bool through_forces = settings_.force_space_controls;
  controlColumns(d, s, !through_forces, B);
  if (through_forces) forceSpaceColumns(d, s, B);
  // Activations (skip the position and velocity stages), one column each.
  for (int i = 0; i < na; ++i) {
    nudgedStep(d, s, d->act + i, eps, mjSTAGE_VEL, s.plus);
    if (centered) nudgedStep(d, s, d->act + i, -eps, mjSTAGE_VEL, s.minus);
    difference(centered ? s.minus : s.next, s.plus, centered ? 2 * eps : eps, s);
    for (int r = 0; r < nx_; ++r) A(r, 2 * nv + i) = s.delta[r];
  }
  // Velocities (skip the position stage), then positions (everything): column j nudges the
  // j-th DOF of every group at once; each DOF's column takes its own group's rows.
  for (const bool position : {false, true}) {
    for (int j = 0; j < columns; ++j) {
      for (const int sign : {1, -1}) {
        if (sign < 0 && !centered) break;
        if (position) {
          std::fill(s.dpos.begin(), s.dpos.end(), 0.0);
          for (int i = 0; i < nv; ++i)
            if (s.slot[i] == j) s.dpos[i] = 1;
          mj_integratePos(m, d->qpos, s.dpos.data(), sign * eps);
        } else {
          for (int i = 0; i < nv; ++i)
            if (s.slot[i] == j) d->qvel[i] += sign * eps;
        }
        stepSkip(position ? position_model : m, d, position ? mjSTAGE_NONE : mjSTAGE_POS, sign > 0 ? s.plus : s.minus);
        restore(d, s);
      }
      difference(centered ? s.minus : s.next, s.plus, centered ? 2 * eps : eps, s);
      for (int i = 0; i < nv; ++i) {
        if (s.slot[i] != j) continue;
        const int col = position ? i : nv + i;
        for (int r = 0; r < nv; ++r) {
          const bool same = s.representative[r] == s.representative[i];
          A(r, col) = same ? s.delta[r] : 0.0;
          A(nv + r, col) = same ? s.delta[nv + r] : 0.0;
        }
        for (int a = 0; a < na; ++a) A(2 * nv + a, col) = s.delta[2 * nv + a];  // na > 0: one group
      }
    }
  }
  return columns;
}

void FdDerivatives::controlColumns(mjData* d, Scratch& s, bool linear_too, Eigen::MatrixXd& B) const {
  const mjModel* m = model_;
  const double eps = settings_.epsilon;
  const bool centered = settings_.centered;
  // Controls (skip the position and velocity stages); a control at its range's end is
  // nudged inwards (mj_step clamps ctrl, so outwards would read zero).
  for (int i = 0; i < m->nu; ++i) {
    if (linear_actuator_[i] && !linear_too) continue;
    const bool limited = m->actuator_ctrllimited[i];
    const double lo = m->actuator_ctrlrange[2 * i], hi = m->actuator_ctrlrange[2 * i + 1];
    const bool forward = !limited || s.ctrl[i] + eps <= hi;
    const bool backward = (centered || !forward) && (!limited || s.ctrl[i] - eps >= lo);
    if (forward) nudgedStep(d, s, d->ctrl + i, eps, mjSTAGE_VEL, s.plus);
    if (backward) nudgedStep(d, s, d->ctrl + i, -eps, mjSTAGE_VEL, s.minus);
    if (forward && backward) difference(s.minus, s.plus, 2 * eps, s);
    else if (forward) difference(s.next, s.plus, eps, s);
    else if (backward) difference(s.minus, s.next, eps, s);
    else std::fill(s.delta.begin(), s.delta.end(), 0.0);
    for (int r = 0; r < nx_; ++r) B(r, i) = s.delta[r];
  }
}

double FdDerivatives::forceGain(const mjData* d, const Scratch& s, int a) const {
  const mjModel* m = model_;
  const double ctrl = s.ctrl[a];
  // A control outside its range is clamped by the step: it moves nothing (the per-control
  // nudge reads zero too). At the range's end it is free (nudged inwards).
  if (m->actuator_ctrllimited[a] && !mjDISABLED(mjDSBL_CLAMPCTRL) &&
      (ctrl < m->actuator_ctrlrange[2 * a] || ctrl > m->actuator_ctrlrange[2 * a + 1]))
    return 0;
  const double gain = m->actuator_gainprm[a * mjNGAIN];
  if (m->actuator_forcelimited[a]) {
    const double* bias = m->actuator_biasprm + a * mjNBIAS;
    const double force = gain * ctrl + (m->actuator_biastype[a] == mjBIAS_AFFINE
                                            ? bias[0] + bias[1] * d->actuator_length[a] + bias[2] * d->actuator_velocity[a]
                                            : 0.0);
    if (force < m->actuator_forcerange[2 * a] || force > m->actuator_forcerange[2 * a + 1]) return 0;
  }
  return gain;
}

void FdDerivatives::forceSpaceColumns(mjData* d, Scratch& s, Eigen::MatrixXd& B) const {
  const mjModel* m = model_;
  const int nv = m->nv;
  const double eps = settings_.epsilon;
  const bool centered = settings_.centered;
  // The DOFs the linear actuators move at this knot (their moments: the nominal step's).
  s.forced_dofs.clear();
  for (int j = 0; j < nv; ++j)
    for (int a = 0; a < m->nu; ++a)
      if (linear_actuator_[a] && d->actuator_moment[a * nv + j] != 0) {
        s.forced_dofs.push_back(j);
        break;
      }
  // d x' / d qfrc_j: a generalised force enters at the acceleration stage, as ctrl does.
  const int forced = static_cast<int>(s.forced_dofs.size());
  for (int k = 0; k < forced; ++k) {
    mjtNum& applied = d->qfrc_applied[s.forced_dofs[k]];
    const mjtNum saved = applied;
    for (const int sign : {1, -1}) {
      if (sign < 0 && !centered) break;
      applied = saved + sign * eps;
      stepSkip(m, d, mjSTAGE_VEL, sign > 0 ? s.plus : s.minus);
      restore(d, s);
      applied = saved;
    }
    difference(centered ? s.minus : s.next, s.plus, centered ? 2 * eps : eps, s);
    for (int r = 0; r < nx_; ++r) s.force_columns(r, k) = s.delta[r];
  }
  // Chain rule: d qfrc / d ctrl_a = moment_a' gain_a.
  for (int a = 0; a < m->nu; ++a) {
    if (!linear_actuator_[a]) continue;
    B.col(a).setZero();
    const double gain = forceGain(d, s, a);
    if (gain == 0) continue;
    for (int k = 0; k < forced; ++k) {
      const double arm = d->actuator_moment[a * nv + s.forced_dofs[k]];
      if (arm != 0) B.col(a) += (gain * arm) * s.force_columns.col(k);
    }
  }
}

void FdDerivatives::compute(adroit::ThreadPool& pool, const std::vector<Eigen::VectorXd>& states,
                            const std::vector<Eigen::VectorXd>& ctrl, const std::vector<double>& times,
                            std::vector<Eigen::MatrixXd>& A, std::vector<Eigen::MatrixXd>& B) {
  const mjModel* m = model_;
  planReuse(states, times);
  pool.parallelForWorkers(evaluate_.size(), [&](std::size_t i, std::size_t w) {
    const int t = computed_[evaluate_[i]];
    mjData* d = data_[w].get();
    setKnotState(m, d, states[t], ctrl[t], times[t]);
    const int columns = knot(d, w, A[t], B[t]);
    if (t == 0) last_state_columns_ = columns;
  });
  for (std::size_t i = 0; i < computed_.size(); ++i) {
    if (source_[i] < 0) continue;
    A[computed_[i]] = kept_[source_[i]].A;
    B[computed_[i]] = kept_[source_[i]].B;
  }
  // Hold each computed linearisation over the skipped knots after it.
  for (std::size_t i = 0; i < computed_.size(); ++i) {
    const int from = computed_[i];
    const int until = i + 1 < computed_.size() ? computed_[i + 1] : horizon_;
    for (int t = from + 1; t < until; ++t) {
      A[t] = A[from];
      B[t] = B[from];
    }
  }
  if (settings_.max_age > 0) keep(states, times, A, B);
}

void FdDerivatives::planReuse(const std::vector<Eigen::VectorXd>& states, const std::vector<double>& times) {
  const int n = static_cast<int>(computed_.size());
  const double max_age = settings_.max_age;
  const double t0 = times[0];
  for (int i = 0; i < n; ++i) source_[i] = max_age > 0 ? nearestKept(states, times, times[computed_[i]], t0) : -1;
  // Refreshes due: n knots every max_age of plan time, n since / max_age for the time since
  // the last call, the fraction carried to the next call. Knots evaluated anyway count; the
  // oldest kept ones (the earliest knot on a tie) make up the rest, so that the refreshes spread
  // evenly over the calls instead of every linearisation expiring in the same one.
  int evaluated = static_cast<int>(std::count(source_.begin(), source_.end(), -1));
  if (max_age > 0) {
    const double since = kept_t0_valid_ ? std::clamp(t0 - kept_t0_, 0.0, max_age) : max_age;
    refreshes_due_ += n * since / max_age;
    const int minimum = std::min(n, static_cast<int>(std::floor(refreshes_due_ + 1e-9)));
    for (; evaluated < minimum; ++evaluated) {
      int oldest = -1;
      for (int i = 0; i < n; ++i)
        if (source_[i] >= 0 && (oldest < 0 || kept_[source_[i]].computed_at < kept_[source_[oldest]].computed_at))
          oldest = i;
      source_[oldest] = -1;
    }
    refreshes_due_ = std::max(0.0, refreshes_due_ - evaluated);
    kept_t0_ = t0;
    kept_t0_valid_ = true;
  }
  evaluate_.clear();
  last_oldest_age_ = 0;
  for (int i = 0; i < n; ++i) {
    if (source_[i] < 0) evaluate_.push_back(i);
    else last_oldest_age_ = std::max(last_oldest_age_, t0 - kept_[source_[i]].computed_at);
  }
}

int FdDerivatives::nearestKept(const std::vector<Eigen::VectorXd>& states, const std::vector<double>& times,
                               double time, double t0) {
  // No farther in time than the hold reaches (skip - 1 knots; half a knot without a skip).
  const double window = std::max(settings_.skip - 1.0, 0.5) * model_->opt.timestep * (1 + 1e-9);
  int best = -1;
  for (int j = 0; j < static_cast<int>(kept_.size()); ++j) {
    const Linearisation& k = kept_[j];
    const double age = t0 - k.computed_at;
    if (!k.valid || !(age >= 0 && age <= settings_.max_age * (1 + 1e-9)) || std::fabs(k.time - time) > window) continue;
    if (best < 0 || std::fabs(k.time - time) < std::fabs(kept_[best].time - time)) best = j;
  }
  if (best < 0) return -1;
  // Has the trajectory moved where that linearisation was taken? This call's states at its
  // time against its state: the plan's change, not the motion over the offset in time (the
  // hold's approximation, which the window bounds).
  interpolate(states, times, kept_[best].time, x_at_);
  if (stateDistance(x_at_, kept_[best].state) > settings_.reuse_tolerance) return -1;
  return best;
}

void FdDerivatives::interpolate(const std::vector<Eigen::VectorXd>& states, const std::vector<double>& times,
                                double time, Eigen::VectorXd& out) const {
  // Linear between the knots (quaternions unnormalised: mj_differentiatePos takes them), held
  // beyond the ends.
  const int last = static_cast<int>(times.size()) - 1;
  const double s = std::clamp((time - times[0]) / model_->opt.timestep, 0.0, static_cast<double>(last));
  const int i = std::min(static_cast<int>(s), std::max(last - 1, 0));
  const double a = s - i;
  out = (1 - a) * states[i] + a * states[std::min(i + 1, last)];
}

double FdDerivatives::stateDistance(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  const mjModel* m = model_;
  mj_differentiatePos(m, dq_.data(), 1.0, b.data(), a.data());
  double distance = dq_.cwiseAbs().maxCoeff();
  // A velocity difference dv moves the next knot by dt dv: compared in the same units.
  for (int k = 0; k < m->nv; ++k)
    distance = std::max(distance, m->opt.timestep * std::fabs(a[m->nq + k] - b[m->nq + k]));
  for (int k = m->nq + m->nv; k < m->nq + m->nv + m->na; ++k) distance = std::max(distance, std::fabs(a[k] - b[k]));
  return distance;
}

void FdDerivatives::keep(const std::vector<Eigen::VectorXd>& states, const std::vector<double>& times,
                         const std::vector<Eigen::MatrixXd>& A, const std::vector<Eigen::MatrixXd>& B) {
  for (std::size_t i = 0; i < computed_.size(); ++i) {
    Linearisation& k = next_[i];
    if (source_[i] >= 0) {  // the same linearisation, kept on
      k = kept_[source_[i]];
      continue;
    }
    const int t = computed_[i];
    k.valid = true;
    k.time = times[t];
    k.computed_at = times[0];
    k.state = states[t];
    k.A = A[t];
    k.B = B[t];
  }
  std::swap(kept_, next_);  // equal sizes: no allocation
}

}  // namespace adroit_mpc
