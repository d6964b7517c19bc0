#include "adroit_mpc/fd_derivatives.h"

#include "adroit_mpc/planner.h"  // integrateAfterForward

#include <algorithm>
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
  }
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

  // Controls (skip the position and velocity stages); a control at its range's end is
  // nudged inwards (mj_step clamps ctrl, so outwards would read zero).
  for (int i = 0; i < m->nu; ++i) {
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

void FdDerivatives::compute(adroit::ThreadPool& pool, const std::vector<Eigen::VectorXd>& states,
                            const std::vector<Eigen::VectorXd>& ctrl, const std::vector<double>& times,
                            std::vector<Eigen::MatrixXd>& A, std::vector<Eigen::MatrixXd>& B) {
  const mjModel* m = model_;
  pool.parallelForWorkers(computed_.size(), [&](std::size_t i, std::size_t w) {
    const int t = computed_[i];
    mjData* d = data_[w].get();
    setKnotState(m, d, states[t], ctrl[t], times[t]);
    const int columns = knot(d, w, A[t], B[t]);
    if (i == 0) last_state_columns_ = columns;
  });
  // Hold each computed linearisation over the skipped knots after it.
  for (std::size_t i = 0; i < computed_.size(); ++i) {
    const int from = computed_[i];
    const int until = i + 1 < computed_.size() ? computed_[i + 1] : horizon_;
    for (int t = from + 1; t < until; ++t) {
      A[t] = A[from];
      B[t] = B[from];
    }
  }
}

}  // namespace adroit_mpc
