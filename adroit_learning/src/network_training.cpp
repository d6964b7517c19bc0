#include "adroit_learning/network_training.h"

#include "network_model.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <random>
#include <stdexcept>
#include <thread>

namespace adroit {

namespace {

constexpr int kMaxEpochs = 1000000, kMaxBatch = 1 << 20, kMaxThreads = 1024;
constexpr int64_t kEvaluationChunk = 8192;  // samples per forward pass when measuring a loss
const double kNaN = std::numeric_limits<double>::quiet_NaN();

struct Split {
  std::vector<int64_t> train, held_out;
};

// Columns into training and held-out sets: whole groups (rollouts) when the data has them.
Split splitSamples(const NetworkDataset& data, double fraction, std::mt19937_64& rng) {
  const int64_t n = data.inputs.cols();
  Split split;
  if (fraction == 0) {
    split.train.resize(static_cast<std::size_t>(n));
    std::iota(split.train.begin(), split.train.end(), 0);
    return split;
  }
  std::vector<bool> held(static_cast<std::size_t>(n), false);
  const double wanted = fraction * static_cast<double>(n);
  if (data.group.empty()) {
    if (n < 2) throw std::invalid_argument("network training: one sample cannot be split into training and held-out sets");
    std::vector<int64_t> order(static_cast<std::size_t>(n));
    std::iota(order.begin(), order.end(), 0);
    std::shuffle(order.begin(), order.end(), rng);
    const auto count = std::clamp<int64_t>(std::llround(wanted), 1, n - 1);
    for (int64_t i = 0; i < count; ++i) held[static_cast<std::size_t>(order[static_cast<std::size_t>(i)])] = true;
  } else {
    std::vector<int> groups = data.group;
    std::sort(groups.begin(), groups.end());
    groups.erase(std::unique(groups.begin(), groups.end()), groups.end());
    if (groups.size() < 2)
      throw std::invalid_argument("network training: a held-out set of whole rollouts needs at least two groups, the data has " +
                                  std::to_string(groups.size()));
    std::shuffle(groups.begin(), groups.end(), rng);
    // Whole groups until the held-out set holds the fraction; the last group always trains.
    std::vector<int> chosen;
    int64_t count = 0;
    for (std::size_t g = 0; g + 1 < groups.size() && (chosen.empty() || count < wanted); ++g) {
      chosen.push_back(groups[g]);
      count += std::count(data.group.begin(), data.group.end(), groups[g]);
    }
    std::sort(chosen.begin(), chosen.end());
    for (int64_t i = 0; i < n; ++i)
      held[static_cast<std::size_t>(i)] = std::binary_search(chosen.begin(), chosen.end(), data.group[static_cast<std::size_t>(i)]);
  }
  for (int64_t i = 0; i < n; ++i) (held[static_cast<std::size_t>(i)] ? split.held_out : split.train).push_back(i);
  return split;
}

void requireUsableData(const NetworkDataset& data, const NetworkPolicy& policy) {
  const auto n = data.inputs.cols();
  if (n == 0) throw std::invalid_argument("network training: no samples");
  if (data.inputs.rows() != policy.inputSize() || data.actions.rows() != policy.nu() || data.actions.cols() != n)
    throw std::invalid_argument("network training: inputs " + std::to_string(data.inputs.rows()) + "x" +
                                std::to_string(n) + " and actions " + std::to_string(data.actions.rows()) + "x" +
                                std::to_string(data.actions.cols()) + ", the policy needs " +
                                std::to_string(policy.inputSize()) + " inputs and " + std::to_string(policy.nu()) +
                                " actions per sample");
  if (!data.group.empty() && static_cast<Eigen::Index>(data.group.size()) != n)
    throw std::invalid_argument("network training: " + std::to_string(data.group.size()) + " group ids for " +
                                std::to_string(n) + " samples");
  for (const auto* m : {&data.inputs, &data.actions}) {
    Eigen::Index row = 0, col = 0;
    if (!m->allFinite()) {
      (!m->array().isFinite()).cast<int>().maxCoeff(&row, &col);
      throw std::invalid_argument(std::string("network training: ") + (m == &data.inputs ? "input" : "action") + " " +
                                  std::to_string(row) + " of sample " + std::to_string(col) + " is not finite");
    }
  }
}

// Mean and standard deviation per row over the training columns.
void rowStatistics(const Eigen::MatrixXf& m, const std::vector<int64_t>& columns, Eigen::VectorXf& mean,
                   Eigen::VectorXf& std) {
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(m.rows()), squares = Eigen::VectorXd::Zero(m.rows());
  for (int64_t c : columns) {
    const Eigen::VectorXd v = m.col(c).cast<double>();
    sum += v;
    squares += v.cwiseAbs2();
  }
  const double n = static_cast<double>(columns.size());
  const Eigen::VectorXd mu = sum / n;
  mean = mu.cast<float>();
  std = (squares / n - mu.cwiseAbs2()).cwiseMax(0.0).cwiseSqrt().cast<float>();
}

// (m - mean) / std column by column, as a torch batch (N x rows) that owns its memory.
torch::Tensor normalisedBatch(const Eigen::MatrixXf& m, const Eigen::VectorXf& mean, const Eigen::VectorXf& std) {
  Eigen::MatrixXf normalised = ((m.colwise() - mean).array().colwise() / std.array()).matrix();
  // Column-major rows x N is row-major N x rows.
  return torch::from_blob(normalised.data(), {m.cols(), m.rows()}, torch::kFloat32).clone();
}

double meanSquaredError(Mlp& mlp, const torch::Tensor& x, const torch::Tensor& y) {
  if (x.size(0) == 0) return kNaN;
  torch::NoGradGuard no_grad;
  double sum = 0;
  for (int64_t begin = 0; begin < x.size(0); begin += kEvaluationChunk) {
    const int64_t end = std::min(begin + kEvaluationChunk, x.size(0));
    sum += (mlp->forward(x.slice(0, begin, end)) - y.slice(0, begin, end)).pow(2).sum().item<double>();
  }
  return sum / static_cast<double>(y.numel());
}

torch::Tensor indexTensor(const std::vector<int64_t>& indices) {
  return torch::from_blob(const_cast<int64_t*>(indices.data()), {static_cast<int64_t>(indices.size())}, torch::kInt64)
      .clone();
}

// Torch's intra-op threads for training, and back to 1 (the policy's inference setting) on
// every way out.
class TrainingThreads {
 public:
  explicit TrainingThreads(int threads) {
    const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    at::set_num_threads(threads > 0 ? threads : cores);
  }
  ~TrainingThreads() { at::set_num_threads(1); }
  TrainingThreads(const TrainingThreads&) = delete;
  TrainingThreads& operator=(const TrainingThreads&) = delete;
};

}  // namespace

std::string NetworkTrainingSettings::validate() const {
  if (epochs < 1 || epochs > kMaxEpochs)
    return "epochs must be in [1, " + std::to_string(kMaxEpochs) + "], got " + std::to_string(epochs);
  if (batch_size < 1 || batch_size > kMaxBatch)
    return "batch_size must be in [1, " + std::to_string(kMaxBatch) + "], got " + std::to_string(batch_size);
  if (!(std::isfinite(learning_rate) && learning_rate > 0))
    return "learning_rate must be a positive number, got " + std::to_string(learning_rate);
  if (!(held_out_fraction >= 0 && held_out_fraction < 1))
    return "held_out_fraction must be in [0, 1), got " + std::to_string(held_out_fraction);
  if (!(std::isfinite(weight_decay) && weight_decay >= 0))
    return "weight_decay must be a non-negative number, got " + std::to_string(weight_decay);
  if (threads < 0 || threads > kMaxThreads)
    return "threads must be in [0, " + std::to_string(kMaxThreads) + "] (0 = all cores), got " + std::to_string(threads);
  return "";
}

NetworkPolicy trainNetworkPolicy(const NetworkDataset& data, const NetworkSpec& spec,
                                 const NetworkTrainingSettings& settings, NetworkPolicyMetadata metadata,
                                 NetworkTrainingReport* report,
                                 std::function<void(int epoch, double train, double held_out)> progress) {
  const auto started = std::chrono::steady_clock::now();
  const std::string problem = settings.validate();
  if (!problem.empty()) throw std::invalid_argument("network training: " + problem);
  torch::manual_seed(settings.seed);  // the initial weights
  NetworkPolicy policy(std::move(metadata), spec);
  requireUsableData(data, policy);
  std::mt19937_64 rng(settings.seed);
  const Split split = splitSamples(data, settings.held_out_fraction, rng);

  NetworkNormalisation normalisation;
  rowStatistics(data.inputs, split.train, normalisation.input_mean, normalisation.input_std);
  rowStatistics(data.actions, split.train, normalisation.action_mean, normalisation.action_std);
  policy.setNormalisation(normalisation);  // floors the standard deviations
  const NetworkNormalisation& n = policy.normalisation();
  const torch::Tensor x = normalisedBatch(data.inputs, n.input_mean, n.input_std);
  const torch::Tensor y = normalisedBatch(data.actions, n.action_mean, n.action_std);
  const torch::Tensor train_index = indexTensor(split.train), held_index = indexTensor(split.held_out);
  const torch::Tensor x_train = x.index_select(0, train_index), y_train = y.index_select(0, train_index);
  const torch::Tensor x_held = x.index_select(0, held_index), y_held = y.index_select(0, held_index);

  NetworkTrainingReport local;
  NetworkTrainingReport& r = report ? *report : local;
  r = NetworkTrainingReport{};
  r.train_samples = static_cast<int>(split.train.size());
  r.held_out_samples = static_cast<int>(split.held_out.size());
  // In normalised units the training mean predicts 0.
  r.mean_predictor_held_out_loss = split.held_out.empty() ? kNaN : y_held.pow(2).mean().item<double>();

  const TrainingThreads threads(settings.threads);
  Mlp& mlp = policy.model().mlp;
  torch::optim::Adam adam(mlp->parameters(),
                          torch::optim::AdamOptions(settings.learning_rate).weight_decay(settings.weight_decay));
  std::vector<int64_t> order(split.train.size());
  std::iota(order.begin(), order.end(), 0);
  for (int epoch = 1; epoch <= settings.epochs; ++epoch) {
    std::shuffle(order.begin(), order.end(), rng);
    const torch::Tensor shuffled = indexTensor(order);
    for (int64_t begin = 0; begin < shuffled.size(0); begin += settings.batch_size) {
      const torch::Tensor batch = shuffled.slice(0, begin, std::min<int64_t>(begin + settings.batch_size, shuffled.size(0)));
      adam.zero_grad();
      const torch::Tensor loss = torch::mse_loss(mlp->forward(x_train.index_select(0, batch)), y_train.index_select(0, batch));
      loss.backward();
      adam.step();
    }
    r.train_loss.push_back(meanSquaredError(mlp, x_train, y_train));
    r.held_out_loss.push_back(meanSquaredError(mlp, x_held, y_held));
    if (progress) progress(epoch, r.train_loss.back(), r.held_out_loss.back());
  }
  policy.parametersChanged();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return policy;
}

std::string networkLossCsv(const NetworkTrainingReport& report) {
  std::string csv = "epoch,train_loss,held_out_loss,mean_predictor_loss\n";
  char line[128];
  for (std::size_t e = 0; e < report.train_loss.size(); ++e) {
    const double held = e < report.held_out_loss.size() ? report.held_out_loss[e] : kNaN;
    std::snprintf(line, sizeof line, "%zu,%.9g,%.9g,%.9g\n", e + 1, report.train_loss[e], held,
                  report.mean_predictor_held_out_loss);
    csv += line;
  }
  return csv;
}

}  // namespace adroit
