// The torch side of NetworkPolicy (network_policy.h), private to adroit_learning_network:
// shared by inference (network_policy.cpp) and training (network_training.cpp), so both run
// one module and one definition of the architecture.
#pragma once
#include <adroit_learning/network_policy.h>

#include <torch/torch.h>

#include <vector>

namespace adroit {

// input -> [Linear + ReLU] x hidden_layers -> Linear -> outputs, on normalised values.
class MlpImpl : public torch::nn::Cloneable<MlpImpl> {
 public:
  MlpImpl(int inputs, const NetworkSpec& spec, int outputs);
  // Builds the layers (Cloneable's contract: clone() calls it, then copies the parameters).
  void reset() override;
  // N x inputs -> N x outputs; the graph for training.
  torch::Tensor forward(torch::Tensor x);

  std::vector<torch::nn::Linear> layers;

 private:
  int inputs_, outputs_;
  NetworkSpec spec_;
};
TORCH_MODULE(Mlp);

struct NetworkModel {
  NetworkModel(int inputs, const NetworkSpec& spec, int outputs);
  // A deep copy: its own parameters and buffers.
  NetworkModel(const NetworkModel& other);
  NetworkModel& operator=(const NetworkModel&) = delete;

  // Rebuilds the views inference reads (transposed weights), after the parameters were
  // replaced or changed. Called by every constructor.
  void prepareInference();
  // Normalised input in `input` -> normalised actions, written to outputs.back() without
  // allocating (addmm into the preallocated layer outputs: the same kernel Linear runs).
  const float* infer();

  Mlp mlp;
  std::vector<float> input;          // normalised network input (batch of one)
  torch::Tensor input_tensor;        // 1 x inputs, on input's memory (from_blob)
  std::vector<torch::Tensor> weights_transposed, outputs;
};

}  // namespace adroit
