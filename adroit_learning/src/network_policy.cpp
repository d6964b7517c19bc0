#include "adroit_learning/network_policy.h"

#include <adroit_core/number_text.h>
#include <adroit_core/word_list.h>
#include <adroit_learning/policy_loader.h>

#include <adroit_core/bounded_file.h>
#include <adroit_learning/matrix_file.h>
#include <adroit_learning/policy_file.h>

#include "network_model.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>

namespace adroit {

namespace {

constexpr const char* kMagic = "adroit_network_policy";
constexpr const char* kMatricesLine = "matrices";
constexpr double kMaxVolts = 5.0;
constexpr int kMaxNames = 100000;  // joints, cylinders, touch sensors, state entries

bool hasWhitespace(const std::string& s) {
  return std::any_of(s.begin(), s.end(), [](char c) { return std::isspace(static_cast<unsigned char>(c)); });
}

// Whole decimal number with nothing around it.
bool parseWholeNumber(const std::string& text, long& out) {
  if (text.empty() || std::isspace(static_cast<unsigned char>(text[0]))) return false;
  char* end = nullptr;
  errno = 0;
  out = std::strtol(text.c_str(), &end, 10);
  return errno == 0 && *end == '\0';
}

// "entry 3 is 'a' where the robot has 'b'", or the counts when one list is a prefix.
std::string firstDifference(const std::vector<std::string>& policy, const std::vector<std::string>& robot) {
  for (std::size_t i = 0; i < std::min(policy.size(), robot.size()); ++i)
    if (policy[i] != robot[i])
      return "entry " + std::to_string(i) + " is '" + policy[i] + "' where the robot has '" + robot[i] + "'";
  return std::to_string(policy.size()) + " entries where the robot has " + std::to_string(robot.size());
}

bool allFinite(const Eigen::Ref<const Eigen::MatrixXf>& m) { return m.allFinite(); }

}  // namespace

// ---- observation sets --------------------------------------------------------------------

std::string name(ObservationSet set) {
  switch (set) {
    case ObservationSet::full: return "full";
    case ObservationSet::partial: return "partial";
    case ObservationSet::no_touch: return "no_touch";
  }
  return "unknown";
}

ObservationSet observationSetFromName(const std::string& text) {
  for (ObservationSet set : {ObservationSet::full, ObservationSet::partial, ObservationSet::no_touch})
    if (name(set) == text) return set;
  throw std::invalid_argument("unknown observation set '" + text + "' (valid: full, partial, no_touch)");
}

// ---- network input -----------------------------------------------------------------------

NetworkInput::NetworkInput(ObservationSet set, const StateLayout& layout, int touch_count)
    : NetworkInput(set, layout.describe(), touch_count) {
  if (state_size_ != layout.nx())
    throw std::logic_error("StateLayout::describe() gives " + std::to_string(state_size_) + " entries, nx() is " +
                           std::to_string(layout.nx()));
}

NetworkInput::NetworkInput(ObservationSet set, const std::string& state_layout, int touch_count)
    : set_(set), touch_count_(touch_count) {
  if (touch_count < 0 || touch_count > kMaxNames)
    throw std::invalid_argument("touch sensor count " + std::to_string(touch_count) + " is outside [0, " +
                                std::to_string(kMaxNames) + "]");
  const bool keep_object = set == ObservationSet::full;
  for (const std::string& block : splitWords(state_layout)) {
    const auto colon = block.rfind(':');
    long length = 0;
    if (colon == std::string::npos || colon == 0 || !parseWholeNumber(block.substr(colon + 1), length) ||
        length < 0 || length > kMaxNames)
      throw std::invalid_argument("state layout '" + state_layout + "': block '" + block +
                                  "' is not '<name>:<size>' with a size in [0, " + std::to_string(kMaxNames) + "]");
    const bool object_block = block.compare(0, 7, "object_") == 0;
    if (length > 0 && (keep_object || !object_block)) {
      // Adjacent kept blocks become one range: fewer loops per inference.
      if (!state_ranges_.empty() && state_ranges_.back().begin + state_ranges_.back().length == state_size_)
        state_ranges_.back().length += static_cast<int>(length);
      else
        state_ranges_.push_back({state_size_, static_cast<int>(length)});
    }
    state_size_ += static_cast<int>(length);
    if (state_size_ > kMaxNames) throw std::invalid_argument("state layout '" + state_layout + "' is too large");
  }
  if (state_size_ == 0) throw std::invalid_argument("state layout '" + state_layout + "' has no entries");
  size_ = readsTouch() ? touch_count_ : 0;
  for (const Range& r : state_ranges_) size_ += r.length;
}

void NetworkInput::fill(const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& touch,
                        float* out) const {
  if (x.size() != state_size_)
    throw std::invalid_argument("network input: the state has " + std::to_string(x.size()) +
                                " entries, the policy's layout " + std::to_string(state_size_));
  if (readsTouch() && touch.size() != touch_count_)
    throw std::invalid_argument("network input: " + std::to_string(touch.size()) + " touch values, the policy reads " +
                                std::to_string(touch_count_));
  for (const Range& r : state_ranges_)
    for (int i = 0; i < r.length; ++i) *out++ = static_cast<float>(x[r.begin + i]);
  if (readsTouch())
    for (int i = 0; i < touch_count_; ++i) *out++ = static_cast<float>(touch[i]);
}

// ---- spec and metadata -------------------------------------------------------------------

std::string NetworkSpec::validate() const {
  if (hidden_layers < 1 || hidden_layers > kMaxNetworkLayers)
    return "hidden_layers must be in [1, " + std::to_string(kMaxNetworkLayers) + "], got " + std::to_string(hidden_layers);
  if (units < 1 || units > kMaxNetworkUnits)
    return "units must be in [1, " + std::to_string(kMaxNetworkUnits) + "], got " + std::to_string(units);
  return "";
}

NetworkPolicyMetadata NetworkPolicyMetadata::forLayout(const StateLayout& layout, std::vector<std::string> touch,
                                                       ObservationSet observation, std::string task, std::string scene,
                                                       double control_dt) {
  NetworkPolicyMetadata m;
  m.task = std::move(task);
  m.scene = std::move(scene);
  m.control_dt = control_dt;
  m.observation = observation;
  m.joints = layout.joint_names;
  m.cylinders = layout.cylinder_names;
  m.touch = std::move(touch);
  for (int c : layout.action_cylinders) m.actions.push_back(layout.cylinder_names[c]);
  m.state_layout = layout.describe();
  return m;
}

std::string NetworkPolicyMetadata::validate() const {
  // Every name is one token: the file's header lists them separated by spaces.
  const auto badNames = [](const char* what, const std::vector<std::string>& names) -> std::string {
    if (names.size() > static_cast<std::size_t>(kMaxNames)) return std::string(what) + ": too many names";
    for (const auto& n : names)
      if (n.empty() || hasWhitespace(n)) return std::string(what) + ": name '" + n + "' is empty or has whitespace";
    return "";
  };
  if (hasWhitespace(task) || hasWhitespace(scene)) return "task and scene must be single words";
  if (!(std::isfinite(control_dt) && control_dt > 0)) return "control_dt must be a positive number of seconds";
  std::string problem = badNames("joints", joints);
  if (problem.empty()) problem = badNames("cylinders", cylinders);
  if (problem.empty()) problem = badNames("touch", touch);
  if (problem.empty()) problem = badNames("actions", actions);
  if (!problem.empty()) return problem;
  if (actions.empty()) return "actions: none (the network needs at least one output)";
  for (const auto& a : actions)
    if (std::find(cylinders.begin(), cylinders.end(), a) == cylinders.end())
      return "actions: '" + a + "' is not one of the cylinders";
  if (state_layout.find('\n') != std::string::npos) return "state_layout: more than one line";
  try {
    (void)NetworkInput(observation, state_layout, static_cast<int>(touch.size()));
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

// ---- torch module ------------------------------------------------------------------------

MlpImpl::MlpImpl(int inputs, const NetworkSpec& spec, int outputs) : inputs_(inputs), outputs_(outputs), spec_(spec) {
  reset();
}

void MlpImpl::reset() {
  layers.clear();
  int in = inputs_;
  for (int l = 0; l <= spec_.hidden_layers; ++l) {
    const int out = l < spec_.hidden_layers ? spec_.units : outputs_;
    layers.push_back(register_module("linear" + std::to_string(l), torch::nn::Linear(in, out)));
    in = out;
  }
}

torch::Tensor MlpImpl::forward(torch::Tensor x) {
  for (std::size_t l = 0; l + 1 < layers.size(); ++l) x = torch::relu(layers[l]->forward(x));
  return layers.back()->forward(x);
}

NetworkModel::NetworkModel(int inputs, const NetworkSpec& spec, int outputs)
    : mlp(inputs, spec, outputs), input(static_cast<std::size_t>(inputs), 0.0f) {
  prepareInference();
}

NetworkModel::NetworkModel(const NetworkModel& other)
    : mlp(std::dynamic_pointer_cast<MlpImpl>(other.mlp->clone())), input(other.input.size(), 0.0f) {
  prepareInference();
}

void NetworkModel::prepareInference() {
  torch::NoGradGuard no_grad;
  weights_transposed.clear();
  outputs.clear();
  for (const auto& layer : mlp->layers) {
    // A view of the parameter (no copy): training's in-place updates show through it.
    weights_transposed.push_back(layer->weight.detach().t());
    outputs.push_back(torch::empty({1, layer->weight.size(0)}, torch::kFloat32));
  }
  input_tensor = torch::from_blob(input.data(), {1, static_cast<int64_t>(input.size())}, torch::kFloat32);
}

const float* NetworkModel::infer() {
  c10::InferenceMode inference;
  const torch::Tensor* in = &input_tensor;
  for (std::size_t l = 0; l < outputs.size(); ++l) {
    // What Linear::forward computes for a 2-D input (addmm(bias, x, W^T)), into a kept tensor.
    at::addmm_out(outputs[l], mlp->layers[l]->bias, *in, weights_transposed[l]);
    if (l + 1 < outputs.size()) at::relu_(outputs[l]);
    in = &outputs[l];
  }
  return outputs.back().data_ptr<float>();
}

// ---- policy ------------------------------------------------------------------------------

NetworkPolicy::NetworkPolicy(NetworkPolicyMetadata metadata, const NetworkSpec& spec)
    : metadata_(std::move(metadata)), spec_(spec) {
  std::string problem = spec_.validate();
  if (problem.empty()) problem = metadata_.validate();
  if (!problem.empty()) throw std::invalid_argument("network policy: " + problem);
  input_ = NetworkInput(metadata_.observation, metadata_.state_layout, static_cast<int>(metadata_.touch.size()));
  at::set_num_threads(1);  // global: see the constructor's comment in network_policy.h
  model_ = std::make_unique<NetworkModel>(input_.size(), spec_, nu());
  NetworkNormalisation identity;
  identity.input_mean = Eigen::VectorXf::Zero(input_.size());
  identity.input_std = Eigen::VectorXf::Ones(input_.size());
  identity.action_mean = Eigen::VectorXf::Zero(nu());
  identity.action_std = Eigen::VectorXf::Ones(nu());
  setNormalisation(std::move(identity));
}

NetworkPolicy::NetworkPolicy(const NetworkPolicy& other)
    : metadata_(other.metadata_), spec_(other.spec_), input_(other.input_), normalisation_(other.normalisation_),
      input_scale_(other.input_scale_), model_(std::make_unique<NetworkModel>(*other.model_)) {}

NetworkPolicy& NetworkPolicy::operator=(const NetworkPolicy& other) {
  if (this != &other) *this = NetworkPolicy(other);
  return *this;
}

NetworkPolicy::NetworkPolicy(NetworkPolicy&&) noexcept = default;
NetworkPolicy& NetworkPolicy::operator=(NetworkPolicy&&) noexcept = default;
NetworkPolicy::~NetworkPolicy() = default;

void NetworkPolicy::setNormalisation(NetworkNormalisation n) {
  const int d = input_.size();
  if (n.input_mean.size() != d || n.input_std.size() != d || n.action_mean.size() != nu() || n.action_std.size() != nu())
    throw std::invalid_argument("network normalisation: " + std::to_string(d) + " inputs and " + std::to_string(nu()) +
                                " actions expected");
  if (!allFinite(n.input_mean) || !allFinite(n.input_std) || !allFinite(n.action_mean) || !allFinite(n.action_std))
    throw std::invalid_argument("network normalisation: a mean or standard deviation is not finite");
  if ((n.input_std.array() < 0).any() || (n.action_std.array() < 0).any())
    throw std::invalid_argument("network normalisation: a standard deviation is negative");
  const auto floor = [](Eigen::VectorXf& s) { s = (s.array() < kMinNetworkStd).select(1.0f, s); };
  floor(n.input_std);
  floor(n.action_std);
  normalisation_ = std::move(n);
  input_scale_ = normalisation_.input_std.cwiseInverse();
}

void NetworkPolicy::action(int, const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& touch,
                           Eigen::Ref<Eigen::VectorXd> u) {
  if (u.size() != nu())
    throw std::invalid_argument("network policy: action has " + std::to_string(u.size()) + " entries, the policy " +
                                std::to_string(nu()));
  input_.fill(x, touch, model_->input.data());
  Eigen::Map<Eigen::VectorXf> in(model_->input.data(), input_.size());
  in = (in - normalisation_.input_mean).cwiseProduct(input_scale_);
  const float* out = model_->infer();
  for (int k = 0; k < nu(); ++k) {
    const double a = static_cast<double>(out[k]) * normalisation_.action_std[k] + normalisation_.action_mean[k];
    u[k] = std::isnan(a) ? a : std::clamp(a, -kMaxVolts, kMaxVolts);
  }
}

std::string NetworkPolicy::mismatch(const std::vector<std::string>& joints, const std::vector<std::string>& cylinders,
                                    const std::vector<std::string>& touch, const StateLayout& layout) const {
  const std::string who = "network policy for task '" + metadata_.task + "': ";
  if (metadata_.joints != joints) return who + "joints differ from the robot's: " + firstDifference(metadata_.joints, joints);
  if (metadata_.cylinders != cylinders)
    return who + "cylinders differ from the robot's: " + firstDifference(metadata_.cylinders, cylinders);
  // A network that does not read touch runs on a robot with any touch sensors.
  if (input_.readsTouch() && metadata_.touch != touch)
    return who + "touch sensors differ from the robot's: " + firstDifference(metadata_.touch, touch);
  if (metadata_.state_layout != layout.describe())
    return who + "state layout '" + metadata_.state_layout + "', the task on this robot gives '" + layout.describe() + "'";
  std::vector<std::string> actions;
  for (int c : layout.action_cylinders) actions.push_back(layout.cylinder_names.at(c));
  if (metadata_.actions != actions)
    return who + "action cylinders differ from the task's: " + firstDifference(metadata_.actions, actions);
  return "";
}

Eigen::MatrixXf NetworkPolicy::weight(int layer) const {
  const torch::Tensor w = model_->mlp->layers.at(static_cast<std::size_t>(layer))->weight.detach().contiguous();
  // Torch is row-major (out x in); Eigen's default column-major.
  return Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
      w.data_ptr<float>(), w.size(0), w.size(1));
}

Eigen::VectorXf NetworkPolicy::bias(int layer) const {
  const torch::Tensor b = model_->mlp->layers.at(static_cast<std::size_t>(layer))->bias.detach().contiguous();
  return Eigen::Map<const Eigen::VectorXf>(b.data_ptr<float>(), b.size(0));
}

void NetworkPolicy::setLayer(int layer, const Eigen::MatrixXf& w, const Eigen::VectorXf& b) {
  if (layer < 0 || layer >= layerCount())
    throw std::invalid_argument("network layer " + std::to_string(layer) + " outside [0, " +
                                std::to_string(layerCount() - 1) + "]");
  auto& linear = model_->mlp->layers[static_cast<std::size_t>(layer)];
  const auto rows = linear->weight.size(0), cols = linear->weight.size(1);
  if (w.rows() != rows || w.cols() != cols || b.size() != rows)
    throw std::invalid_argument("network layer " + std::to_string(layer) + ": weight " + std::to_string(w.rows()) + "x" +
                                std::to_string(w.cols()) + " and bias " + std::to_string(b.size()) + ", expected " +
                                std::to_string(rows) + "x" + std::to_string(cols) + " and " + std::to_string(rows));
  if (!w.allFinite() || !b.allFinite())
    throw std::invalid_argument("network layer " + std::to_string(layer) + ": a weight or bias is not finite");
  const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> row_major = w;
  torch::NoGradGuard no_grad;
  linear->weight.copy_(torch::from_blob(const_cast<float*>(row_major.data()), {rows, cols}, torch::kFloat32));
  linear->bias.copy_(torch::from_blob(const_cast<float*>(b.data()), {rows}, torch::kFloat32));
}

Eigen::MatrixXf NetworkPolicy::predict(const Eigen::MatrixXf& inputs) const {
  if (inputs.rows() != input_.size())
    throw std::invalid_argument("network predict: inputs have " + std::to_string(inputs.rows()) + " rows, the network " +
                                std::to_string(input_.size()));
  const auto n = inputs.cols();
  // Column-major d x N is row-major N x d: torch's batch layout, no transpose needed.
  Eigen::MatrixXf normalised =
      ((inputs.colwise() - normalisation_.input_mean).array().colwise() * input_scale_.array()).matrix();
  torch::NoGradGuard no_grad;
  const torch::Tensor out =
      model_->mlp->forward(torch::from_blob(normalised.data(), {n, inputs.rows()}, torch::kFloat32)).contiguous();
  Eigen::MatrixXf actions = Eigen::Map<const Eigen::MatrixXf>(out.data_ptr<float>(), nu(), n);
  return ((actions.array().colwise() * normalisation_.action_std.array()).colwise() + normalisation_.action_mean.array())
      .matrix();
}

void NetworkPolicy::parametersChanged() { model_->prepareInference(); }

// ---- file --------------------------------------------------------------------------------

namespace {

Eigen::MatrixXd column(const Eigen::VectorXf& v) { return v.cast<double>(); }

// The header's `key value` lines up to the `matrices` line, and where the blocks after it start.
struct Header {
  std::map<std::string, std::string> fields;
  std::size_t matrices_offset = 0;
};

const std::vector<std::string>& headerKeys() {
  static const std::vector<std::string> keys = {"task",   "scene",        "control_dt", "observation", "hidden_layers",
                                                "units",  "inputs",       "state_layout", "joints",    "cylinders",
                                                "touch",  "actions"};
  return keys;
}

Header parseHeader(const std::string& path, const std::string& text) {
  std::size_t pos = text.find('\n');
  const std::string first = text.substr(0, pos == std::string::npos ? text.size() : pos);
  const std::vector<std::string> magic = splitWords(first);
  if (magic.size() != 2 || magic[0] != kMagic)
    throw PolicyFileError(path + ": not an adroit network policy (first line '" + first.substr(0, 60) + "')");
  if (magic[1] != std::to_string(kNetworkPolicyFormatVersion))
    throw PolicyFileError(path + ": format version " + magic[1].substr(0, 20) + ", this build reads version " +
                          std::to_string(kNetworkPolicyFormatVersion));
  Header header;
  while (pos != std::string::npos) {
    const std::size_t begin = pos + 1;
    if (begin >= text.size()) break;
    const std::size_t end = text.find('\n', begin);
    const std::string line = text.substr(begin, end == std::string::npos ? std::string::npos : end - begin);
    pos = end;
    if (line == kMatricesLine) {
      header.matrices_offset = end == std::string::npos ? text.size() : end + 1;
      return header;
    }
    const std::size_t space = line.find(' ');
    const std::string key = line.substr(0, space), value = space == std::string::npos ? "" : line.substr(space + 1);
    if (std::find(headerKeys().begin(), headerKeys().end(), key) == headerKeys().end())
      throw PolicyFileError(path + ": unknown header field '" + key.substr(0, 60) + "'");
    if (!header.fields.emplace(key, value).second) throw PolicyFileError(path + ": header field '" + key + "' twice");
  }
  throw PolicyFileError(path + ": truncated: no 'matrices' line after the header");
}

// A header field that must be a whole number in [low, high].
int headerInt(const std::string& path, const std::map<std::string, std::string>& fields, const std::string& key,
              long low, long high) {
  long value = 0;
  if (!parseWholeNumber(fields.at(key), value) || value < low || value > high)
    throw PolicyFileError(path + ": header field '" + key + "' must be a whole number in [" + std::to_string(low) +
                          ", " + std::to_string(high) + "], got '" + fields.at(key).substr(0, 40) + "'");
  return static_cast<int>(value);
}

NetworkPolicyMetadata readMetadata(const std::string& path, const std::map<std::string, std::string>& fields) {
  NetworkPolicyMetadata m;
  m.task = fields.at("task");
  m.scene = fields.at("scene");
  const std::string& dt = fields.at("control_dt");
  char* end = nullptr;
  m.control_dt = std::strtod(dt.c_str(), &end);
  if (dt.empty() || *end != '\0')
    throw PolicyFileError(path + ": header field 'control_dt': not a number: '" + dt.substr(0, 40) + "'");
  try {
    m.observation = observationSetFromName(fields.at("observation"));
  } catch (const std::invalid_argument& e) {
    throw PolicyFileError(path + ": header field 'observation': " + e.what());
  }
  m.joints = splitWords(fields.at("joints"));
  m.cylinders = splitWords(fields.at("cylinders"));
  m.touch = splitWords(fields.at("touch"));
  m.actions = splitWords(fields.at("actions"));
  m.state_layout = fields.at("state_layout");
  const std::string problem = m.validate();
  if (!problem.empty()) throw PolicyFileError(path + ": header: " + problem);
  return m;
}

// Each value of the block as a float: finite doubles beyond float's range are refused too.
Eigen::MatrixXf floatBlock(const std::string& path, const MatrixFile& file, const std::string& block, int rows,
                           int cols) {
  const Eigen::MatrixXd& m = file.get(block, rows, cols);
  if (m.cwiseAbs().maxCoeff() > static_cast<double>(std::numeric_limits<float>::max()))
    throw PolicyFileError(path + ": block '" + block + "': a value beyond the range of a float");
  return m.cast<float>();
}

}  // namespace

void writeNetworkPolicyFile(const std::string& path, const NetworkPolicy& policy) {
  const NetworkPolicyMetadata& m = policy.metadata();
  std::ostringstream out;
  out << kMagic << " " << kNetworkPolicyFormatVersion << "\n"
      << "task " << m.task << "\n"
      << "scene " << m.scene << "\n"
      << "control_dt " << exactNumber(m.control_dt) << "\n"
      << "observation " << name(m.observation) << "\n"
      << "hidden_layers " << policy.spec().hidden_layers << "\n"
      << "units " << policy.spec().units << "\n"
      << "inputs " << policy.inputSize() << "\n"
      << "state_layout " << m.state_layout << "\n"
      << "joints" << joinWords(m.joints) << "\n"
      << "cylinders" << joinWords(m.cylinders) << "\n"
      << "touch" << joinWords(m.touch) << "\n"
      << "actions" << joinWords(m.actions) << "\n"
      << kMatricesLine << "\n";
  MatrixFile blocks(path);
  const NetworkNormalisation& n = policy.normalisation();
  blocks.set("input_mean", column(n.input_mean));
  blocks.set("input_std", column(n.input_std));
  blocks.set("action_mean", column(n.action_mean));
  blocks.set("action_std", column(n.action_std));
  for (int l = 0; l < policy.layerCount(); ++l) {
    // Floats as %.17g doubles: the text reads back to the same float.
    blocks.set(MatrixFile::stepName("weight", l), policy.weight(l).cast<double>());
    blocks.set(MatrixFile::stepName("bias", l), column(policy.bias(l)));
  }
  writeFileAtomically(path, out.str() + blocks.text());
}

NetworkPolicy readNetworkPolicyFile(const std::string& path) {
  std::string text;
  try {
    text = readBoundedFile(path, kMaxPolicyFileBytes);
  } catch (const FileError& e) {
    throw PolicyFileError(e.what());
  }
  if (text.empty()) throw PolicyFileError(path + ": empty file");
  const Header header = parseHeader(path, text);
  for (const auto& key : headerKeys())
    if (!header.fields.count(key)) throw PolicyFileError(path + ": header field '" + key + "' missing");
  const NetworkPolicyMetadata metadata = readMetadata(path, header.fields);
  NetworkSpec spec;
  spec.hidden_layers = headerInt(path, header.fields, "hidden_layers", 1, kMaxNetworkLayers);
  spec.units = headerInt(path, header.fields, "units", 1, kMaxNetworkUnits);
  const NetworkInput input(metadata.observation, metadata.state_layout, static_cast<int>(metadata.touch.size()));
  const int inputs = headerInt(path, header.fields, "inputs", 1, kMaxNames);
  if (inputs != input.size())
    throw PolicyFileError(path + ": header says " + std::to_string(inputs) + " inputs, observation '" +
                          name(metadata.observation) + "' of its state layout and " +
                          std::to_string(metadata.touch.size()) + " touch sensors gives " +
                          std::to_string(input.size()));
  const int nu = static_cast<int>(metadata.actions.size());
  try {
    // The header becomes blank lines: MatrixFile's messages then give the file's line numbers.
    const auto header_lines = std::count(text.begin(), text.begin() + static_cast<long>(header.matrices_offset), '\n');
    text.replace(0, header.matrices_offset, static_cast<std::size_t>(header_lines), '\n');
    const MatrixFile file = MatrixFile::parse(text, path);
    const std::size_t blocks = 4 + 2 * static_cast<std::size_t>(spec.hidden_layers + 1);
    if (file.blockCount() != blocks)
      throw PolicyFileError(path + ": " + std::to_string(file.blockCount()) + " blocks, a network of " +
                            std::to_string(spec.hidden_layers) + " hidden layers has " + std::to_string(blocks) +
                            " (truncated?)");
    // Every shape is checked (and every value converted) before the network is allocated.
    NetworkNormalisation n;
    n.input_mean = floatBlock(path, file, "input_mean", inputs, 1);
    n.input_std = floatBlock(path, file, "input_std", inputs, 1);
    n.action_mean = floatBlock(path, file, "action_mean", nu, 1);
    n.action_std = floatBlock(path, file, "action_std", nu, 1);
    if ((n.input_std.array() <= 0).any() || (n.action_std.array() <= 0).any())
      throw PolicyFileError(path + ": a standard deviation is not positive");
    std::vector<Eigen::MatrixXf> weights;
    std::vector<Eigen::VectorXf> biases;
    for (int l = 0, in = inputs; l <= spec.hidden_layers; ++l) {
      const int out = l < spec.hidden_layers ? spec.units : nu;
      weights.push_back(floatBlock(path, file, MatrixFile::stepName("weight", l), out, in));
      biases.push_back(floatBlock(path, file, MatrixFile::stepName("bias", l), out, 1));
      in = out;
    }
    NetworkPolicy policy(metadata, spec);
    policy.setNormalisation(std::move(n));
    for (int l = 0; l <= spec.hidden_layers; ++l) policy.setLayer(l, weights[l], biases[l]);
    return policy;
  } catch (const MatrixFileError& e) {
    throw PolicyFileError(e.what());
  }
}

void registerNetworkPolicyReader() {
  registerPolicyReader("adroit_network_policy", [](const std::string& path, const PolicyContext&, PolicyOrigin& origin) {
    auto policy = std::make_unique<NetworkPolicy>(readNetworkPolicyFile(path));
    origin.task = policy->metadata().task;
    origin.scene = policy->metadata().scene;
    origin.control_dt = policy->metadata().control_dt;
    return std::unique_ptr<Policy>(std::move(policy));
  });
}

}  // namespace adroit
