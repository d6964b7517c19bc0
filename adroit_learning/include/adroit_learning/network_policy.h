// The neural-network policy of thesis 11.6: a time-invariant multilayer perceptron from the
// robot's state (and touch sensors) to valve commands, trained by supervised learning on the
// actions of trajectory-centric controllers (network_training.h). ROS-free; the torch module
// stays behind this header (src/network_model.h), so users of the policy need no torch
// headers.
//
// Inputs are normalised with stored per-input mean and standard deviation, outputs
// de-normalised with the per-action ones, and the action is clamped to the valve range
// [-5, 5] V. Files: writeNetworkPolicyFile / readNetworkPolicyFile below (text, versioned,
// like policy_file.h's).
#pragma once
#include <adroit_learning/policy.h>
#include <adroit_learning/trajectory_cost.h>

#include <Eigen/Dense>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace adroit {

// What the network sees (thesis 11.6, "inputs"):
//   full     = the whole state x, then the touch sensors
//   partial  = x without the object's pose and velocity (what a robot without motion capture
//              knows), then the touch sensors
//   no_touch = x without the object blocks, without touch
enum class ObservationSet { full, partial, no_touch };
std::string name(ObservationSet set);
// Throws std::invalid_argument naming the valid names ("full", "partial", "no_touch").
ObservationSet observationSetFromName(const std::string& name);

// Which entries of (x, touch) the network reads, in order. Built from the state layout's
// description (StateLayout::describe(), the string policy files store), so a network read from
// a file selects exactly the entries it was trained on; blocks named object_* are the
// object's.
class NetworkInput {
 public:
  NetworkInput() = default;
  NetworkInput(ObservationSet set, const StateLayout& layout, int touch_count);
  // Throws std::invalid_argument when the description does not parse ("name:size" tokens).
  NetworkInput(ObservationSet set, const std::string& state_layout, int touch_count);

  int size() const { return size_; }
  int stateSize() const { return state_size_; }   // nx the input expects
  int touchCount() const { return touch_count_; }
  bool readsTouch() const { return set_ != ObservationSet::no_touch; }
  ObservationSet set() const { return set_; }
  // Writes size() floats to out. x must have stateSize() entries and touch touchCount() (when
  // read), else std::invalid_argument. Object entries of x are never read by partial and
  // no_touch, nor touch by no_touch.
  void fill(const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& touch,
            float* out) const;

 private:
  struct Range {
    int begin, length;  // entries of x
  };
  ObservationSet set_ = ObservationSet::full;
  std::vector<Range> state_ranges_;
  int state_size_ = 0, touch_count_ = 0, size_ = 0;
};

// Thesis 11.6: 6 hidden layers of 150 ReLU units; the small variant 4 x 80.
struct NetworkSpec {
  int hidden_layers = 6;
  int units = 150;
  std::string validate() const;  // "" or one line
};
constexpr int kMaxNetworkLayers = 64, kMaxNetworkUnits = 4096;

// What the network was trained for and with; a file's header.
struct NetworkPolicyMetadata {
  std::string task, scene;
  double control_dt = 0;  // s
  ObservationSet observation = ObservationSet::full;
  std::vector<std::string> joints, cylinders, touch;
  std::vector<std::string> actions;  // cylinder name of each action entry (StateLayout::action_cylinders)
  std::string state_layout;          // StateLayout::describe()

  // Joints, cylinders, actions and state layout from the layout; the rest from the arguments.
  static NetworkPolicyMetadata forLayout(const StateLayout& layout, std::vector<std::string> touch,
                                         ObservationSet observation, std::string task = "", std::string scene = "",
                                         double control_dt = 0);
  // "" or one line: empty or multi-word names, actions that are not cylinders, a state layout
  // that does not parse, a control step that is not positive.
  std::string validate() const;
};

// Per-input and per-action mean and standard deviation (inputs: NetworkInput order).
struct NetworkNormalisation {
  Eigen::VectorXf input_mean, input_std, action_mean, action_std;
};
// A standard deviation below this is taken as 1: the input is constant in the data (a locked
// cylinder's pressure), and dividing by ~0 would turn noise into huge inputs.
constexpr float kMinNetworkStd = 1e-6f;

struct NetworkModel;  // torch module and inference buffers (src/network_model.h)

class NetworkPolicy : public Policy {
 public:
  // A network with torch's default initialisation (seed it with torch::manual_seed through
  // trainNetworkPolicy) and the identity normalisation. Throws std::invalid_argument for
  // metadata or a spec that do not validate.
  //
  // Sets torch's intra-op threads to 1 for the whole process (at::set_num_threads is global):
  // one batch-1 inference per control step is too small to gain from threads, and handing it
  // to a pool costs more (and jitters more) than it saves. Training raises it for its own
  // duration and sets it back (network_training.h).
  NetworkPolicy(NetworkPolicyMetadata metadata, const NetworkSpec& spec);
  // Copies are deep (own module, own buffers): one copy per thread may run action() at once.
  NetworkPolicy(const NetworkPolicy& other);
  NetworkPolicy& operator=(const NetworkPolicy& other);
  NetworkPolicy(NetworkPolicy&&) noexcept;
  NetworkPolicy& operator=(NetworkPolicy&&) noexcept;
  ~NetworkPolicy() override;

  std::string kind() const override { return "network"; }
  int horizon() const override { return 0; }
  void start(const Eigen::Ref<const Eigen::VectorXd>&) override {}
  // u = clamp(network(x, touch), -5, 5). The input and every layer's output live in buffers
  // allocated once (torch still makes a few small view objects per operation); so not
  // thread-safe on one object. A non-finite input gives a non-finite action, which the
  // caller's finiteness check (and StateLayout::command) meets. Wrong sizes throw
  // std::invalid_argument.
  void action(int t, const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& touch,
              Eigen::Ref<Eigen::VectorXd> u) override;
  std::string mismatch(const std::vector<std::string>& joints, const std::vector<std::string>& cylinders,
                       const std::vector<std::string>& touch, const StateLayout& layout) const override;

  const NetworkPolicyMetadata& metadata() const { return metadata_; }
  const NetworkSpec& spec() const { return spec_; }
  const NetworkInput& input() const { return input_; }
  int inputSize() const { return input_.size(); }
  int nu() const { return static_cast<int>(metadata_.actions.size()); }

  const NetworkNormalisation& normalisation() const { return normalisation_; }
  // Sizes must match, every value be finite and no standard deviation negative (else
  // std::invalid_argument); standard deviations below kMinNetworkStd become 1.
  void setNormalisation(NetworkNormalisation normalisation);

  // Linear layers 0 .. hidden_layers (the last one is the output layer): weight (out x in) and
  // bias (out). setLayer checks the shape and finiteness (std::invalid_argument).
  int layerCount() const { return spec_.hidden_layers + 1; }
  Eigen::MatrixXf weight(int layer) const;
  Eigen::VectorXf bias(int layer) const;
  void setLayer(int layer, const Eigen::MatrixXf& weight, const Eigen::VectorXf& bias);

  // Actions (nu x N, not clamped) for raw network inputs (inputs x N), through the same module
  // that training optimises: for evaluation and tests, not for the control loop.
  Eigen::MatrixXf predict(const Eigen::MatrixXf& inputs) const;

  // The torch side, for network_training.cpp (an incomplete type elsewhere).
  NetworkModel& model() { return *model_; }
  // After the module's parameters changed in place (training): refreshes the inference views.
  void parametersChanged();

 private:
  NetworkPolicyMetadata metadata_;
  NetworkSpec spec_;
  NetworkInput input_;
  NetworkNormalisation normalisation_;
  Eigen::VectorXf input_scale_;  // 1 / input_std, so action() multiplies
  std::unique_ptr<NetworkModel> model_;
};

// The network file: a versioned, self-describing text file (header of `key value` lines, then
// `matrices` and MatrixFile blocks), written atomically:
//
//   adroit_network_policy 1
//   task rotate_vertical_cw
//   scene hand
//   control_dt 0.040000000000000001
//   observation partial
//   hidden_layers 6
//   units 150
//   inputs 105
//   state_layout q:24 object_position:3 ...
//   joints <names>
//   cylinders <names>
//   touch <names>
//   actions <names>
//   matrices
//   input_mean <inputs> 1      input_std, action_mean, action_std (<nu> 1) likewise
//   weight.0 <units> <inputs>  bias.0 <units> 1   ...   weight.<L> <nu> <units>  bias.<L> <nu> 1
constexpr int kNetworkPolicyFormatVersion = 1;

// Throws PolicyFileError naming the path when it cannot be written (an old file stays).
void writeNetworkPolicyFile(const std::string& path, const NetworkPolicy& policy);
// Throws PolicyFileError "<path>: <what>" for anything but a regular file of at most
// kMaxPolicyFileBytes, another magic or version, a missing or bad header field, an unknown
// observation set, blocks missing or of other shapes than the header gives (checked before the
// network is allocated), non-finite values or ones a float cannot hold, standard deviations
// that are not positive.
NetworkPolicy readNetworkPolicyFile(const std::string& path);

// Registers readNetworkPolicyFile with loadPolicy (policy_loader.h) for `adroit_network_policy`
// files. Programs that load policies call it once at their start (explicitly: a static
// initialiser in a shared library may never run when the linker drops the library).
void registerNetworkPolicyReader();

}  // namespace adroit
