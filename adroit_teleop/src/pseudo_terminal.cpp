#include "adroit_teleop/pseudo_terminal.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <stdexcept>

#include "adroit_teleop/serial_port.h"

namespace adroit::teleop {

namespace {

[[noreturn]] void fail(const std::string& what, int err) {
  throw std::runtime_error("pseudo-terminal: " + what + ": " + std::strerror(err));
}

// The target of the symbolic link at `path`, or "" when it is not a readable link.
std::string linkTarget(const std::string& path) {
  char buf[4096];
  const ssize_t n = readlink(path.c_str(), buf, sizeof buf - 1);
  return n < 0 ? std::string() : std::string(buf, static_cast<std::size_t>(n));
}

}  // namespace

PseudoTerminal::PseudoTerminal(const std::string& link) {
  try {
    master_ = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (master_ < 0) fail("posix_openpt", errno);
    if (grantpt(master_) != 0) fail("grantpt", errno);
    if (unlockpt(master_) != 0) fail("unlockpt", errno);
    const char* name = ptsname(master_);
    if (!name) fail("ptsname", errno);
    slave_name_ = name;
    slave_ = ::open(slave_name_.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (slave_ < 0) fail("cannot open " + slave_name_, errno);
    makeRaw(slave_, 115200, "pseudo-terminal " + slave_name_);  // a pty ignores the rate

    if (!link.empty()) {
      struct stat st {};
      if (lstat(link.c_str(), &st) == 0 && !S_ISLNK(st.st_mode))
        throw std::runtime_error("pseudo-terminal: " + link + " exists and is not a symbolic link; not replacing it");
      // Make the new link beside the old one, then rename over it: the path never dangles.
      const std::string tmp = link + ".tmp" + std::to_string(getpid());
      ::unlink(tmp.c_str());
      if (symlink(slave_name_.c_str(), tmp.c_str()) != 0) fail("cannot create link " + tmp, errno);
      if (rename(tmp.c_str(), link.c_str()) != 0) {
        const int err = errno;
        ::unlink(tmp.c_str());
        fail("cannot create link " + link, err);
      }
      link_ = link;
    }
  } catch (...) {
    close();
    throw;
  }
}

PseudoTerminal::~PseudoTerminal() { close(); }

void PseudoTerminal::close() {
  // Remove the link only while it is ours: another emulator may have taken the path since.
  if (!link_.empty() && linkTarget(link_) == slave_name_) ::unlink(link_.c_str());
  link_.clear();
  if (slave_ >= 0) ::close(slave_);
  if (master_ >= 0) ::close(master_);
  slave_ = master_ = -1;
}

}  // namespace adroit::teleop
