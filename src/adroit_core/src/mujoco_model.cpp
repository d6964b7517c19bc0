#include "adroit_core/mujoco_model.h"

#include <cstring>
#include <sstream>

#include "adroit_core/bounded_file.h"

namespace adroit {
namespace {

constexpr int kErrorSize = 1000;
constexpr size_t kMaxModelFileBytes = 256 * kMiB;

std::string trimmed(const char* text) {
  std::string s(text);
  // MuJoCo messages span lines ("Error ...\nElement ..., line N"); keep them on one line.
  for (char& c : s) {
    if (c == '\n' || c == '\r') c = ' ';
  }
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s;
}

bool endsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

}  // namespace

LoadedModel loadModelFile(const std::string& path) {
  // A model path comes from a parameter: a FIFO would block MuJoCo's reader for good, a device
  // feed it without end. The largest scene is ~100 kB of MJCF, a compiled one a few MB.
  try {
    requireRegularFile(path, kMaxModelFileBytes);
  } catch (const FileError& e) {
    throw ModelLoadError(std::string("cannot load model: ") + e.what());
  }
  char error[kErrorSize] = "";
  mjModel* m = nullptr;
  if (endsWith(path, ".mjb")) {
    m = mj_loadModel(path.c_str(), nullptr);
    if (!m) std::snprintf(error, kErrorSize, "could not read binary model");
  } else {
    m = mj_loadXML(path.c_str(), nullptr, error, kErrorSize);
  }
  if (!m) {
    throw ModelLoadError("cannot load model '" + path + "': " + trimmed(error));
  }
  return {ModelPtr(m), trimmed(error)};
}

LoadedModel loadModelString(const std::string& xml) {
  // mjVFS is about 2 MB: keep it off the stack.
  auto vfs = std::make_unique<mjVFS>();
  mj_defaultVFS(vfs.get());
  const char* name = "inline_model.xml";
  if (mj_makeEmptyFileVFS(vfs.get(), name, static_cast<int>(xml.size())) != 0) {
    throw ModelLoadError("cannot load model '<string>': virtual file system refused the text");
  }
  const int index = mj_findFileVFS(vfs.get(), name);
  std::memcpy(vfs->filedata[index], xml.data(), xml.size());
  char error[kErrorSize] = "";
  mjModel* m = mj_loadXML(name, vfs.get(), error, kErrorSize);
  mj_deleteVFS(vfs.get());
  if (!m) {
    throw ModelLoadError("cannot load model '<string>': " + trimmed(error));
  }
  return {ModelPtr(m), trimmed(error)};
}

DataPtr makeData(const mjModel* model) {
  mjData* d = mj_makeData(model);
  if (!d) throw std::runtime_error("mj_makeData failed (out of memory?)");
  return DataPtr(d);
}

ModelPtr copyModel(const mjModel* model) {
  mjModel* m = mj_copyModel(nullptr, model);
  if (!m) throw std::runtime_error("mj_copyModel failed (out of memory?)");
  return ModelPtr(m);
}

DataPtr copyData(const mjModel* model, const mjData* data) {
  mjData* d = mj_copyData(nullptr, model, data);
  if (!d) throw std::runtime_error("mj_copyData failed (out of memory?)");
  return DataPtr(d);
}

int warningCount(const mjData* data) {
  int n = 0;
  for (int i = 0; i < mjNWARNING; ++i) n += data->warning[i].number;
  return n;
}

std::string warningSummary(const mjData* data) {
  static const char* kNames[mjNWARNING] = {"inertia", "contactfull", "cnstrfull", "vgeomfull",
                                           "badqpos", "badqvel", "badqacc", "badctrl"};
  std::ostringstream out;
  for (int i = 0; i < mjNWARNING; ++i) {
    if (data->warning[i].number > 0) {
      if (out.tellp() > 0) out << ", ";
      out << kNames[i] << " x" << data->warning[i].number << " (last info " << data->warning[i].lastinfo
          << ")";
    }
  }
  return out.str();
}

}  // namespace adroit
