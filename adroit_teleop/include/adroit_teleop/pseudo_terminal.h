// A pseudo-terminal standing in for a serial device, with a symbolic link (e.g.
// /tmp/adroit_glove -> /dev/pts/7) so a driver opens it by a fixed path like a real port.
// The glove emulator program owns one; destroying it is "unplugging the glove": the master
// closes (the driver's reads see a hang-up) and the link disappears.
#pragma once

#include <string>

namespace adroit::teleop {

class PseudoTerminal {
 public:
  // Opens a master/slave pair (posix_openpt, grantpt, unlockpt, ptsname), puts the slave in
  // raw mode (no echo: the host must not read its own commands back) and, when `link` is not
  // empty, points `link` at the slave. A stale symbolic link at that path is replaced; any
  // other file there is left alone and refused. Throws std::runtime_error naming what failed.
  explicit PseudoTerminal(const std::string& link = "");
  ~PseudoTerminal();
  PseudoTerminal(const PseudoTerminal&) = delete;
  PseudoTerminal& operator=(const PseudoTerminal&) = delete;

  // Non-blocking master: the emulator reads commands from and writes frames to it.
  int master() const { return master_; }
  const std::string& slaveName() const { return slave_name_; }
  const std::string& link() const { return link_; }

  // Closes both ends and removes the link if it still points at this slave.
  void close();

 private:
  int master_ = -1;
  // A slave descriptor of our own: without one, a Linux pty master reports POLLHUP (and
  // reads fail with EIO) whenever no driver has the slave open, which would make the
  // emulator busy-poll until a driver comes.
  int slave_ = -1;
  std::string slave_name_, link_;
};

}  // namespace adroit::teleop
