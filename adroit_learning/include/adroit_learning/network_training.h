// Supervised training of a NetworkPolicy (thesis 11.6): regression of the actions of
// trajectory-centric controllers on the network's inputs, Adam on the mean squared error in
// normalised action units, with a held-out set for the learning curve.
#pragma once
#include <adroit_learning/network_policy.h>

#include <Eigen/Dense>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace adroit {

// One column per sample. inputs: the policy's inputs (NetworkInput::fill order), actions: the
// valve commands (V) the network should give there.
struct NetworkDataset {
  Eigen::MatrixXf inputs;   // inputs x N
  Eigen::MatrixXf actions;  // nu x N
  // Optional rollout id per column. When given, the held-out set is made of whole rollouts:
  // neighbouring samples of one rollout are nearly equal, and holding out single columns would
  // measure interpolation between them rather than generalisation.
  std::vector<int> group;
};

struct NetworkTrainingSettings {
  int epochs = 100;
  int batch_size = 256;
  double learning_rate = 1e-3;
  double held_out_fraction = 0.1;  // of the samples (of the rollouts with groups); 0 = none
  std::uint64_t seed = 1;          // initial weights, split and batch order
  double weight_decay = 0;         // Adam's L2 penalty
  // Torch intra-op threads while training; 0 = all cores. On cores shared with other work
  // use 1: OpenMP's waiting threads spin, and a 2-core machine under load trained 6 x 150
  // 20-50 times slower on 2 threads than on 1.
  int threads = 0;
  std::string validate() const;    // "" or one line
};

// Losses are mean squared errors in normalised action units (per action: (a - mean) / std of
// the training set), averaged over actions and samples: the mean predictor scores ~1 on the
// training data.
struct NetworkTrainingReport {
  std::vector<double> train_loss, held_out_loss;  // one per epoch; held-out NaN without a held-out set
  double mean_predictor_held_out_loss = 0;        // the training mean as the prediction (NaN without)
  double seconds = 0;
  int train_samples = 0, held_out_samples = 0;
};

// Trains a fresh network on `data` and returns it with the training set's normalisation.
// Deterministic for a seed and thread count (torch::manual_seed; the split and batch order
// from the seed). Throws std::invalid_argument (one line) for settings, spec or metadata that
// do not validate, empty data, sizes that disagree with the metadata's inputs and actions or
// with each other, non-finite values, a held-out fraction that leaves no training or no
// held-out sample. Torch's intra-op threads are settings.threads during training and 1 after
// (network_policy.h).
NetworkPolicy trainNetworkPolicy(const NetworkDataset& data, const NetworkSpec& spec,
                                 const NetworkTrainingSettings& settings, NetworkPolicyMetadata metadata,
                                 NetworkTrainingReport* report,
                                 std::function<void(int epoch, double train, double held_out)> progress = {});

// "epoch,train_loss,held_out_loss,mean_predictor_loss" and one line per epoch (from 1).
std::string networkLossCsv(const NetworkTrainingReport& report);

}  // namespace adroit
