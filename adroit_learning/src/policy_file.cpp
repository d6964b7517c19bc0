#include "adroit_learning/policy_file.h"

#include <adroit_core/number_text.h>
#include <adroit_core/word_list.h>
#include <adroit_core/bounded_file.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <map>
#include <sstream>
#include <unistd.h>

namespace adroit {

namespace {

constexpr const char* kMagic = "adroit_tvlg_policy";
constexpr const char* kMatrices = "matrices";

// The first name where two lists differ, as "'a' where the robot has 'b'" (or a count).
std::string firstDifference(const std::vector<std::string>& file, const std::vector<std::string>& robot) {
  for (std::size_t i = 0; i < std::min(file.size(), robot.size()); ++i)
    if (file[i] != robot[i]) return "entry " + std::to_string(i) + " is '" + file[i] + "' where the robot has '" + robot[i] + "'";
  return std::to_string(file.size()) + " entries where the robot has " + std::to_string(robot.size());
}

// The line at `pos` (without its newline), advancing `pos` past it; false at the end.
bool nextLine(const std::string& text, std::size_t& pos, std::string& line) {
  if (pos >= text.size()) return false;
  const std::size_t end = std::min(text.find('\n', pos), text.size());
  line.assign(text, pos, end - pos);
  pos = end + 1;
  return true;
}

}  // namespace

void writeFileAtomically(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd < 0) throw PolicyFileError(path + ": cannot write: " + std::strerror(errno));
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string why = std::strerror(errno);
      ::close(fd);
      ::unlink(tmp.c_str());
      throw PolicyFileError(path + ": write failed: " + why);
    }
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    const std::string why = std::strerror(errno);
    ::unlink(tmp.c_str());
    throw PolicyFileError(path + ": write failed: " + why);
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string why = std::strerror(errno);
    ::unlink(tmp.c_str());
    throw PolicyFileError(path + ": cannot replace: " + why);
  }
}

void writePolicyFile(const std::string& path, const PolicyFile& p) {
  std::ostringstream out;
  out << kMagic << " " << kPolicyFormatVersion << "\n"
      << "task " << p.task << "\n"
      << "scene " << p.scene << "\n"
      << "control_dt " << exactNumber(p.control_dt) << "\n"
      << "iteration " << p.iteration << "\n"
      << "cost_mean " << exactNumber(p.cost_mean) << "\n"
      << "locked_command " << exactNumber(p.locked_command) << "\n"
      << "state_layout " << p.state_layout << "\n"
      << "joints" << joinWords(p.joints) << "\n"
      << "cylinders" << joinWords(p.cylinders) << "\n"
      << "actions" << joinWords(p.actions) << "\n"
      << kMatrices << "\n";
  MatrixFile matrices(path);
  writeController(p.controller, matrices);
  writeFileAtomically(path, out.str() + matrices.text());
}

PolicyFile readPolicyFile(const std::string& path) {
  std::string text;
  try {
    text = readBoundedFile(path, kMaxPolicyFileBytes);
  } catch (const FileError& e) {
    throw PolicyFileError(e.what());
  }
  std::size_t pos = 0;  // of the next line in `text` (no copy of it: it can be large)
  std::string line;
  if (!nextLine(text, pos, line)) throw PolicyFileError(path + ": empty file");
  {
    std::istringstream first(line);
    std::string magic;
    int version = 0;
    first >> magic >> version;
    if (magic != kMagic) throw PolicyFileError(path + ": not an adroit_learning policy (first line '" + line.substr(0, 60) + "')");
    if (version != kPolicyFormatVersion)
      throw PolicyFileError(path + ": format version " + std::to_string(version) + ", this build reads version " +
                            std::to_string(kPolicyFormatVersion));
  }
  std::map<std::string, std::string> header;
  bool matrices = false;
  while (nextLine(text, pos, line)) {
    if (line == kMatrices) {
      matrices = true;
      break;
    }
    const auto space = line.find(' ');
    header[line.substr(0, space)] = space == std::string::npos ? "" : line.substr(space + 1);
  }
  if (!matrices) throw PolicyFileError(path + ": truncated: no 'matrices' section");
  const auto field = [&](const std::string& key) -> const std::string& {
    const auto it = header.find(key);
    if (it == header.end()) throw PolicyFileError(path + ": header field '" + key + "' missing");
    return it->second;
  };
  const auto number = [&](const std::string& key) {
    const std::string& text = field(key);
    char* end = nullptr;
    const double x = std::strtod(text.c_str(), &end);
    if (end == text.c_str() || *end != '\0' || (key != "cost_mean" && !std::isfinite(x)))
      throw PolicyFileError(path + ": header field '" + key + "': not a number: '" + text + "'");
    return x;
  };
  PolicyFile p;
  p.task = field("task");
  p.scene = field("scene");
  p.state_layout = field("state_layout");
  p.control_dt = number("control_dt");
  const double iteration = number("iteration");
  if (!(iteration >= 0 && iteration <= 1e9))
    throw PolicyFileError(path + ": header field 'iteration' must be in [0, 1e9], got " + field("iteration"));
  p.iteration = static_cast<int>(iteration);
  p.cost_mean = number("cost_mean");
  p.locked_command = number("locked_command");
  p.joints = splitWords(field("joints"));
  p.cylinders = splitWords(field("cylinders"));
  p.actions = splitWords(field("actions"));
  if (!(p.control_dt > 0)) throw PolicyFileError(path + ": header field 'control_dt' must be positive");
  text.erase(0, pos);  // the matrices
  try {
    const MatrixFile file = MatrixFile::parse(text, path);
    const MatrixDims dims = readDims(file);  // checked sizes; blocks are checked before allocating
    if (dims.nu != static_cast<int>(p.actions.size()))
      throw PolicyFileError(path + ": the controller has " + std::to_string(dims.nu) + " actions, the header names " +
                            std::to_string(p.actions.size()));
    p.controller = readController(file, dims.nx, dims.nu, dims.horizon);
  } catch (const MatrixFileError& e) {
    throw PolicyFileError(e.what());
  }
  return p;
}

std::string policyMismatch(const PolicyFile& p, const std::string& path, const std::vector<std::string>& joints,
                           const std::vector<std::string>& cylinders, const std::string& state_layout) {
  if (p.joints != joints) return path + ": joints differ from the robot's: " + firstDifference(p.joints, joints);
  if (p.cylinders != cylinders)
    return path + ": cylinders differ from the robot's: " + firstDifference(p.cylinders, cylinders);
  if (p.state_layout != state_layout)
    return path + ": state layout '" + p.state_layout + "', the task on this robot gives '" + state_layout + "'";
  return "";
}

}  // namespace adroit
