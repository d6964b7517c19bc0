#include "adroit_core/run_program.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>

extern char** environ;

namespace adroit {

std::string ProgramResult::describe() const {
  if (!started) return error;
  if (timed_out) return "killed after its timeout";
  if (signal != 0) return std::string("ended by signal ") + strsignal(signal);
  return "exit " + std::to_string(exit_code);
}

namespace {

using Clock = std::chrono::steady_clock;

// Reads what is available on `fd` into `out` (up to `limit` bytes kept); false at end of file.
bool drain(int fd, std::string& out, size_t limit) {
  char buffer[4096];
  const ssize_t n = read(fd, buffer, sizeof buffer);
  if (n <= 0) return n < 0 && (errno == EINTR || errno == EAGAIN);
  const size_t keep = out.size() < limit ? std::min(limit - out.size(), static_cast<size_t>(n)) : 0;
  out.append(buffer, keep);
  return true;
}

// Waits for `pid` until the deadline, reading its output pipe (-1: none) meanwhile; false on
// the deadline. After the exit the pipe is read until it is empty.
bool waitUntil(pid_t pid, int out_fd, Clock::time_point deadline, ProgramResult& result, size_t limit, int& status) {
  bool reading = out_fd >= 0, exited = false;
  while (true) {
    if (!exited) {
      const pid_t done = waitpid(pid, &status, WNOHANG);
      exited = done == pid || (done < 0 && errno != EINTR);
    }
    if (exited && !reading) return true;
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
    if (left <= 0) return exited;
    const int wait_ms = exited ? 0 : static_cast<int>(std::min<long long>(left, 20));
    if (reading) {
      pollfd p{out_fd, POLLIN, 0};
      if (poll(&p, 1, wait_ms) > 0) reading = drain(out_fd, result.output, limit);
      else if (exited) return true;  // exited and nothing left to read
    } else {
      usleep(static_cast<useconds_t>(wait_ms) * 1000);
    }
  }
}

}  // namespace

ProgramResult runProgram(const std::vector<std::string>& argv, const ProgramOptions& options) {
  ProgramResult result;
  if (argv.empty() || argv[0].empty()) {
    result.error = "no program to run";
    return result;
  }
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);

  int pipe_fds[2] = {-1, -1};
  if (options.capture_output && pipe2(pipe_fds, O_CLOEXEC) != 0) {
    result.error = std::string("cannot start '") + argv[0] + "': pipe: " + std::strerror(errno);
    return result;
  }
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  if (options.capture_output) posix_spawn_file_actions_adddup2(&actions, pipe_fds[1], 1);
  else if (options.quiet) posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
  if (options.capture_output && options.merge_stderr) posix_spawn_file_actions_adddup2(&actions, pipe_fds[1], 2);
  else if (options.quiet) posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
  posix_spawnattr_t attributes;
  posix_spawnattr_init(&attributes);
  posix_spawnattr_setflags(&attributes, POSIX_SPAWN_SETPGROUP);  // its own group: a timeout kills its children too
  posix_spawnattr_setpgroup(&attributes, 0);

  pid_t pid = -1;
  const int rc = posix_spawnp(&pid, args[0], &actions, &attributes, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  posix_spawnattr_destroy(&attributes);
  if (pipe_fds[1] >= 0) close(pipe_fds[1]);
  if (rc != 0) {
    if (pipe_fds[0] >= 0) close(pipe_fds[0]);
    result.error = std::string("cannot start '") + argv[0] + "': " + std::strerror(rc);
    return result;
  }
  result.started = true;
  const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                            std::chrono::duration<double>(options.timeout_s));
  int status = 0;
  if (!waitUntil(pid, pipe_fds[0], deadline, result, options.max_output, status)) {
    result.timed_out = true;
    kill(-pid, SIGKILL);
    while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
  }
  if (pipe_fds[0] >= 0) close(pipe_fds[0]);
  if (!result.timed_out && WIFEXITED(status)) result.exit_code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) result.signal = WTERMSIG(status);
  return result;
}

}  // namespace adroit
