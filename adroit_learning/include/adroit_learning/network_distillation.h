// Distillation of a library of local TVLG policies into one time-invariant network policy
// (thesis 11.6): every local policy runs its own stochastic controller from its own initial
// state (the tube at the yaw it was trained for), and the network is regressed on the local
// policy's MEAN action at every state visited. Optionally DAgger (Ross, Gordon and Bagnell
// 2011) goes beyond plain cloning: the current network runs from the library's yaws and from
// random ones, the states it reaches are labelled by the local policy nearest in initial yaw,
// added to the data, and the network retrained.
//
// ROS-free: rollouts go through any RolloutBackend (SimRollouts in train_network_policy),
// training through network_training.h.
#pragma once
#include <adroit_learning/network_policy.h>
#include <adroit_learning/network_training.h>
#include <adroit_learning/policy_library.h>
#include <adroit_learning/rollout_backend.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

namespace adroit {

constexpr int kMaxDistillationRollouts = 100000;  // per policy, and per DAgger round
constexpr int kMaxDaggerRounds = 1000;

// A cancel flag was set while rollouts ran; nothing of the interrupted step was kept.
class DistillationCancelled : public std::runtime_error {
 public:
  DistillationCancelled() : std::runtime_error("cancelled") {}
};

// "" when every local policy of `library` can run as `task` on the backend's robot, else one
// line: a library of another task or scene, a policy not read, other joints, cylinders, state
// layout or actions than the task gives on this robot (TvlgPolicy::mismatch), another control
// step or locked-cylinder command than the task's.
std::string libraryProblem(const PolicyLibrary& library, const TrainingTask& task, const StateLayout& layout,
                           const RolloutBackend& backend);

// What one collection step ran and kept.
struct CollectionStats {
  int rollouts = 0;           // run
  int failed = 0;             // not ok (skipped: none of their samples is kept)
  int samples = 0;            // columns added to the dataset
  std::string first_failure;  // the first failed rollout's reason ("" when none failed)
  // Per rollout, in request order: the tube's initial yaw (deg), the library entry whose
  // mean actions labelled it, its group id in the dataset (-1 when it failed).
  std::vector<double> yaws;
  std::vector<int> labelled_by, groups;
};

// Thesis 11.6's training data: for each local policy, `rollouts_per_policy` (thesis: 50)
// rollouts of its stochastic controller (K_t x + k_t + L_t noise_t, its own covariance, white
// noise from smoothedNoise) from its own initial state (the task's, with object_yaw_deg = the
// entry's yaw), for the local horizon. One column per visited state x_t, t < T: input
// NetworkInput::fill(x_t, touch_t), label the local policy's mean action at x_t clamped to the
// valve range, group id = the rollout's index (entry * rollouts_per_policy + i), so the
// held-out set is made of whole rollouts. Failed rollouts are skipped and counted in `stats`.
// Deterministic for a seed (and a deterministic backend). Throws std::invalid_argument for a
// count outside [1, kMaxDistillationRollouts], a library that libraryProblem refuses, an input
// that does not read this layout's state and the backend's touch sensors; DistillationCancelled.
NetworkDataset collectLocalPolicyData(RolloutBackend& backend, const TrainingTask& task, const StateLayout& layout,
                                      const PolicyLibrary& library, int rollouts_per_policy, const NetworkInput& input,
                                      std::uint64_t seed, CollectionStats* stats = nullptr,
                                      const std::atomic<bool>* cancel = nullptr);

// One DAgger aggregation: `rollouts` runs of the current network's mean action (runPolicy) for
// `steps` control steps (0: the task's horizon), rollout i from the library's i-th yaw while
// i < library size, then from yaws uniform in [0, 180) (from `seed`). Every visited state x_t
// of rollout i is labelled with the mean action at step min(t, H - 1) of the local policy
// nearest in initial yaw to rollout i's (nearestPolicyIndex, modulo 180 degrees), clamped to the
// valve range, and appended to `data` under new group ids (one per rollout, above every id
// already there). Returns the samples added. Throws std::invalid_argument for a count outside
// [1, kMaxDistillationRollouts], negative steps, a library that libraryProblem refuses, data
// whose sizes or group ids do not fit the network; DistillationCancelled (data unchanged).
//
// The label is the expert of the rollout's initial yaw, as the nearest-neighbour library of
// 11.5 would choose it. A network with partial or no_touch inputs does not see that yaw: for it
// the labels of nearby states from different yaws can disagree, and only what the rollout
// reveals through touch and proprioception can tell them apart (the thesis' point for those
// inputs). With local policies that do not react to the tube, DAgger rounds then raise the
// held-out loss of those networks rather than lower it.
int aggregateOnPolicyData(RolloutBackend& backend, const TrainingTask& task, const StateLayout& layout,
                          const PolicyLibrary& library, const NetworkPolicy& current, NetworkDataset& data, int rollouts,
                          std::uint64_t seed, int steps = 0, CollectionStats* stats = nullptr,
                          const std::atomic<bool>* cancel = nullptr);

struct DistillationSettings {
  ObservationSet observation = ObservationSet::full;
  NetworkSpec spec;                  // thesis: 6 x 150 (4 x 80 the small one)
  NetworkTrainingSettings training;  // initial weights, split and batch order from training.seed
  int rollouts_per_policy = 50;      // thesis 11.6
  int dagger_rounds = 0;             // 0: plain cloning of the local policies (the thesis)
  int dagger_rollouts = 20;          // network rollouts per round
  int dagger_steps = 0;              // control steps of each; 0 = the task's horizon
  std::uint64_t seed = 1;            // exploration noise of the local policies, DAgger's random yaws
  std::string validate() const;      // "" or one line naming the field
};

// One training of the network: round 0 on the local policies' rollouts, round k >= 1 after the
// k-th DAgger aggregation.
struct DistillationRound {
  int round = 0;
  CollectionStats collection;       // this round's new rollouts
  int dataset_samples = 0;          // all samples the network was trained on (training + held out)
  NetworkTrainingReport training;   // per-epoch losses, the mean predictor's held-out loss
  double collect_seconds = 0, train_seconds = 0;
  double trainLoss() const;         // last epoch's (NaN before training)
  double heldOutLoss() const;
};

struct DistillationReport {
  std::vector<DistillationRound> rounds;
  double seconds = 0;
};

// What distillLibrary reports while it runs.
struct DistillationProgress {
  enum class Stage { collected, epoch, trained };
  Stage stage = Stage::collected;
  int round = 0;
  int epoch = 0;                             // Stage::epoch: 1..epochs
  double train_loss = 0, held_out_loss = 0;  // Stage::epoch
  const DistillationRound* summary = nullptr;  // the round so far (valid during the call)
};
using DistillationProgressFn = std::function<void(const DistillationProgress&)>;

// collect -> train -> dagger_rounds x (aggregate with the last network -> retrain). Every round
// retrains from scratch on the aggregate (trainNetworkPolicy's fresh initialisation, the same
// training seed): DAgger's guarantee is for the learner fitted to the whole aggregated data set,
// and the input/action normalisation is recomputed from that data each round, which weights
// trained under the previous round's normalisation would not match. It costs (rounds + 1)
// trainings, which are cheap next to the rollouts for the thesis' data sizes.
// Returns the last round's network (metadata: task, scene, control step, the layout and the
// backend's touch sensors). Throws std::invalid_argument for settings that do not validate
// (validate(), NetworkSpec, NetworkTrainingSettings) or what collection refuses,
// std::runtime_error when no rollout of a round succeeded (with the first reason),
// DistillationCancelled.
NetworkPolicy distillLibrary(RolloutBackend& backend, const TrainingTask& task, const StateLayout& layout,
                             const PolicyLibrary& library, const DistillationSettings& settings,
                             DistillationReport* report = nullptr, const DistillationProgressFn& progress = {},
                             const std::atomic<bool>* cancel = nullptr);

// "round,epoch,samples,train_loss,held_out_loss,mean_predictor_loss" and one line per epoch of
// every round (epochs from 1 in each round).
std::string distillationLossCsv(const DistillationReport& report);

}  // namespace adroit
