// makeTask and the defaults of every task.
#include <stdexcept>

#include "adroit_mpc/catch_task.h"
#include "adroit_mpc/relocate_task.h"
#include "adroit_mpc/task.h"
#include "adroit_mpc/task_params.h"
#include "adroit_mpc/type_task.h"

namespace adroit_mpc {

namespace {
[[noreturn]] void unknownTask(const std::string& name) {
  throw std::invalid_argument("unknown task '" + name + "' (known: catch, relocate, type)");
}
}  // namespace

std::vector<std::string> taskNames() { return {"catch", "relocate", "type"}; }

TaskParams defaultTaskParams(const std::string& task) {
  if (task == "catch") return CatchTask::defaults();
  if (task == "relocate") return RelocateTask::defaults();
  if (task == "type") return TypeTask::defaults();
  unknownTask(task);
}

std::unique_ptr<Task> makeTask(const std::string& name, const TaskParams& params) {
  if (name == "catch") return std::make_unique<CatchTask>(params);
  if (name == "relocate") return std::make_unique<RelocateTask>(params);
  if (name == "type") return std::make_unique<TypeTask>(params);
  unknownTask(name);
}

}  // namespace adroit_mpc
