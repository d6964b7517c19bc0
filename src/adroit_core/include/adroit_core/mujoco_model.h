// RAII ownership of MuJoCo models and data, with loader errors turned into exceptions.
#pragma once

#include <mujoco/mujoco.h>

#include <memory>
#include <stdexcept>
#include <string>

namespace adroit {

// Thrown when a model cannot be loaded or compiled. what() is one line quoting MuJoCo's
// own message and the source (file path or "<string>").
class ModelLoadError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct ModelDeleter {
  void operator()(mjModel* m) const { mj_deleteModel(m); }
};
struct DataDeleter {
  void operator()(mjData* d) const { mj_deleteData(d); }
};
using ModelPtr = std::unique_ptr<mjModel, ModelDeleter>;
using DataPtr = std::unique_ptr<mjData, DataDeleter>;

// A compiled model together with the compiler's warning text (empty when clean).
struct LoadedModel {
  ModelPtr model;
  std::string warning;
};

// Loads an MJCF (or MJB, by extension) file. Throws ModelLoadError.
LoadedModel loadModelFile(const std::string& path);
// Compiles MJCF text held in memory (no includes of other in-memory files). Throws ModelLoadError.
LoadedModel loadModelString(const std::string& xml);

DataPtr makeData(const mjModel* model);
ModelPtr copyModel(const mjModel* model);
DataPtr copyData(const mjModel* model, const mjData* data);

// Number of runtime warnings (bad qpos/qvel/qacc/ctrl, contact/constraint overflow...) that
// MuJoCo has counted in `data` since the last reset, and a readable summary of them.
int warningCount(const mjData* data);
std::string warningSummary(const mjData* data);

}  // namespace adroit
