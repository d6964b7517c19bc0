#include "adroit_learning/policy_loader.h"

#include <adroit_core/bounded_file.h>
#include <adroit_learning/policy_library.h>
#include <adroit_learning/tvlg_policy.h>

#include <fcntl.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <cstring>
#include <limits>
#include <map>
#include <mutex>
#include <sstream>

namespace adroit {

namespace {

// Enough for any first line of a policy format ("adroit_tvlg_policy 1").
constexpr std::size_t kFirstLineBytes = 256;

std::unique_ptr<Policy> readTvlg(const std::string& path, const PolicyContext&, PolicyOrigin& origin) {
  auto file = std::make_shared<const PolicyFile>(readPolicyFile(path));
  origin.task = file->task;
  origin.scene = file->scene;
  origin.control_dt = file->control_dt;
  return std::make_unique<TvlgPolicy>(std::move(file), path);
}

std::unique_ptr<Policy> readLibrary(const std::string& path, const PolicyContext& context, PolicyOrigin& origin) {
  auto library = std::make_shared<const PolicyLibrary>(readPolicyLibrary(path));
  if (!context.object_geometry)
    throw PolicyFileError(path + ": a policy library needs the scene's object geometry, which the caller did not give");
  const ObjectGeometry object = context.object_geometry(library->scene);
  if (!object.valid())
    throw PolicyFileError(path + ": scene '" + library->scene + "' has no capsule or cylinder object to read a yaw from");
  origin.task = library->task;
  origin.scene = library->scene;
  origin.control_dt = library->entries.front().policy->control_dt;
  return std::make_unique<LibraryPolicy>(std::move(library), object, path);
}

struct Registry {
  std::mutex mutex;
  std::map<std::string, PolicyReader> readers{{"adroit_tvlg_policy", readTvlg},
                                              {"adroit_policy_library", readLibrary}};
};

Registry& registry() {
  static Registry r;  // built on first use: readers may register from static initialisers
  return r;
}

// Formats this build knows of but cannot read until a library registers their reader.
std::string missingReaderHint(const std::string& first_word) {
  if (first_word == "adroit_network_policy") return "network policies need adroit_learning_network";
  return "";
}

// The first line of `path`, read without trusting the file: a regular file only (never blocks
// on a FIFO), at most kFirstLineBytes.
std::string firstLine(const std::string& path) {
  try {
    requireRegularFile(path, std::numeric_limits<std::size_t>::max());  // each reader applies its own limit
  } catch (const FileError& e) {
    throw PolicyFileError(e.what());
  }
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
  if (fd < 0) throw PolicyFileError(path + ": cannot open (" + std::strerror(errno) + ")");
  char buffer[kFirstLineBytes];
  ssize_t n;
  do n = ::read(fd, buffer, sizeof(buffer));
  while (n < 0 && errno == EINTR);
  const int read_errno = errno;
  ::close(fd);
  if (n < 0) throw PolicyFileError(path + ": read failed (" + std::strerror(read_errno) + ")");
  if (n == 0) throw PolicyFileError(path + ": empty file");
  const std::string text(buffer, static_cast<std::size_t>(n));
  return text.substr(0, text.find('\n'));
}

}  // namespace

bool registerPolicyReader(const std::string& first_word, PolicyReader reader) {
  Registry& r = registry();
  std::lock_guard<std::mutex> lock(r.mutex);
  r.readers[first_word] = std::move(reader);
  return true;
}

std::unique_ptr<Policy> loadPolicy(const std::string& path, const PolicyContext& context, PolicyOrigin* origin) {
  const std::string line = firstLine(path);
  std::string first_word;
  std::istringstream(line) >> first_word;
  PolicyReader reader;
  {
    Registry& r = registry();
    std::lock_guard<std::mutex> lock(r.mutex);
    const auto it = r.readers.find(first_word);
    if (it != r.readers.end()) reader = it->second;
  }
  if (!reader) {
    const std::string hint = missingReaderHint(first_word);
    if (!hint.empty()) throw PolicyFileError(path + ": " + hint);
    std::string shown = line.substr(0, 60);
    for (char& c : shown)
      if (!std::isprint(static_cast<unsigned char>(c))) c = '?';  // a binary file's bytes stay out of the log
    throw PolicyFileError(path + ": not a policy file (first line '" + shown + "')");
  }
  PolicyOrigin found;
  found.format = first_word;
  std::unique_ptr<Policy> policy = reader(path, context, found);
  if (!policy) throw PolicyFileError(path + ": the " + first_word + " reader gave no policy");
  if (origin) *origin = found;
  return policy;
}

}  // namespace adroit
