#include "process.hpp"

#include <crumple/core/error.hpp>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <sstream>

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

namespace crumple::cli {

bool on_path(const std::string& program) {
  const char* path = std::getenv("PATH");
  if (path == nullptr) return false;
  std::stringstream in(path);
  for (std::string dir; std::getline(in, dir, ':');) {
    if (dir.empty()) continue;
    const std::filesystem::path candidate = std::filesystem::path(dir) / program;
    if (::access(candidate.c_str(), X_OK) == 0) return true;
  }
  return false;
}

int run_program(const std::vector<std::string>& argv, const std::filesystem::path& cwd) {
  CRUMPLE_CHECK(!argv.empty(), "run_program needs a program name");
  // Everything the child needs is prepared before fork: between fork and exec it only calls
  // async-signal-safe functions (the parent may run other threads).
  std::vector<char*> args;
  args.reserve(argv.size() + 1);
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  const std::string dir = cwd.string();
  int report[2];  // the child writes errno here when chdir or exec fails; closed on exec
  if (::pipe2(report, O_CLOEXEC) != 0) {
    throw Error("cannot start " + argv[0] + ": " + std::strerror(errno));
  }
  const pid_t pid = ::fork();
  if (pid < 0) {
    const int err = errno;
    ::close(report[0]);
    ::close(report[1]);
    throw Error("cannot start " + argv[0] + ": " + std::strerror(err));
  }
  if (pid == 0) {
    ::close(report[0]);
    const int null_fd = ::open("/dev/null", O_RDONLY);
    if (null_fd >= 0) ::dup2(null_fd, STDIN_FILENO);
    if (::chdir(dir.c_str()) == 0) ::execvp(args[0], args.data());
    const int err = errno;
    [[maybe_unused]] const ssize_t n = ::write(report[1], &err, sizeof err);
    ::_exit(127);
  }
  ::close(report[1]);
  int child_errno = 0;
  ssize_t got = 0;
  do {
    got = ::read(report[0], &child_errno, sizeof child_errno);
  } while (got < 0 && errno == EINTR);
  ::close(report[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) throw Error("waiting for " + argv[0] + ": " + std::strerror(errno));
  }
  if (got == static_cast<ssize_t>(sizeof child_errno)) {
    throw Error("cannot run " + argv[0] + " in '" + dir + "': " + std::strerror(child_errno));
  }
  if (WIFSIGNALED(status)) {
    throw Error(argv[0] + " was killed by signal " + std::to_string(WTERMSIG(status)));
  }
  return WEXITSTATUS(status);
}

}  // namespace crumple::cli
