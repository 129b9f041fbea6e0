#include "util/python_worker.h"

#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <thread>

#include <nlohmann/json.hpp>

#include "util/temp_paths.h"

extern char** environ;

namespace carmba {
namespace {

// The interpreter's program (python -c BOOTSTRAP PRELOAD); the job line arrives on stdin.
constexpr const char* kBootstrap = R"PY(
import json, os, runpy, sys, traceback
if sys.path and sys.path[0] == '':
    del sys.path[0]
try:
    exec(sys.argv[1])
except BaseException:
    pass
line = sys.stdin.buffer.readline()
if not line:
    os._exit(0)
job = json.loads(line)
for fd, path in ((1, job['stdout']), (2, job['stderr'])):
    if not path:
        continue
    f = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(f, fd)
    os.close(f)
f = os.open(os.devnull, os.O_RDONLY)
os.dup2(f, 0)
os.close(f)
sys.argv = [job['script']] + job['args']
sys.path.insert(0, os.path.dirname(os.path.abspath(job['script'])))
code = 0
try:
    runpy.run_path(job['script'], run_name='__main__')
except SystemExit as e:
    if e.code is None:
        code = 0
    elif isinstance(e.code, int):
        code = e.code
    else:
        print(e.code, file=sys.stderr)
        code = 1
except BaseException:
    traceback.print_exc()
    code = 1
sys.exit(code)
)PY";

double SecondsSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

int ExitCode(int status) {
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
  return PythonWorker::kCannotRun;
}

}  // namespace

PythonWorker::PythonWorker(const std::string& python, const std::string& preload)
    : python_(python), born_(std::chrono::steady_clock::now()) {
  int fds[2];
  if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, fds) != 0) return;
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, fds[1], STDIN_FILENO);
  std::string c = "-c", boot = kBootstrap, pre = preload;
  char* argv[] = {python_.data(), c.data(), boot.data(), pre.data(), nullptr};
  // The child starts with no signal blocked: it would inherit the mask of the section below.
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  sigset_t none;
  sigemptyset(&none);
  posix_spawnattr_setsigmask(&attr, &none);
  posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGMASK);
  pid_t pid = -1;
  int rc = 0;
  {
    const SignalCriticalSection spawning;  // a SIGTERM now must find the child registered
    rc = ::posix_spawnp(&pid, python_.c_str(), &actions, &attr, argv, environ);
    if (rc == 0) child_slot_ = RegisterChildProcess(pid);
  }
  posix_spawnattr_destroy(&attr);
  posix_spawn_file_actions_destroy(&actions);
  ::close(fds[1]);
  if (rc != 0) {
    ::close(fds[0]);
    return;
  }
  pid_ = pid;
  socket_ = fds[0];
}

void PythonWorker::Reap(int* status) {
  UnregisterChildProcess(child_slot_);  // before waitpid: the pid may be recycled after it
  child_slot_ = -1;
  while (::waitpid(pid_, status, 0) < 0 && errno == EINTR) {
  }
}

PythonWorker::~PythonWorker() {
  if (pid_ > 0 && !waited_) {
    ::kill(pid_, SIGKILL);
    int status = 0;
    Reap(&status);
  }
  if (socket_ >= 0) ::close(socket_);
}

bool PythonWorker::Start(const std::string& script_path,
                         const std::vector<std::string>& args,
                         const std::string& stdout_path,
                         const std::string& stderr_path) {
  if (pid_ <= 0 || started_ || waited_) return false;
  const std::string line = nlohmann::json({{"script", script_path},
                                           {"args", args},
                                           {"stdout", stdout_path},
                                           {"stderr", stderr_path}})
                               .dump() +
                           "\n";
  size_t sent = 0;
  while (sent < line.size()) {
    const ssize_t n = ::send(socket_, line.data() + sent, line.size() - sent, MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;  // the interpreter is gone (Wait reports its exit)
    sent += static_cast<size_t>(n);
  }
  started_ = true;
  job_sent_ = std::chrono::steady_clock::now();
  return true;
}

int PythonWorker::Wait(int timeout_s) {
  if (waited_) return exit_code_;
  waited_ = true;
  if (pid_ <= 0) return exit_code_ = kCannotRun;
  if (!started_) {
    ::kill(pid_, SIGKILL);
  }
  int status = 0;
  if (timeout_s > 0 && started_) {
    for (;;) {
      // Has it exited? (WNOWAIT: not reaped yet, so its pid cannot be recycled before Reap
      // unregisters it.)
      siginfo_t info{};
      const int r = ::waitid(P_PID, static_cast<id_t>(pid_), &info, WEXITED | WNOHANG | WNOWAIT);
      if (r == 0 && info.si_pid == pid_) {
        Reap(&status);
        break;
      }
      if (r < 0 && errno != EINTR) return exit_code_ = kCannotRun;
      if (SecondsSince(job_sent_) > timeout_s) {
        ::kill(pid_, SIGKILL);
        Reap(&status);
        seconds_ = SecondsSince(born_);
        return exit_code_ = kTimedOut;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  } else {
    siginfo_t info{};  // waits for the exit without reaping (see above), then reaps
    while (::waitid(P_PID, static_cast<id_t>(pid_), &info, WEXITED | WNOWAIT) < 0) {
      if (errno != EINTR) return exit_code_ = kCannotRun;
    }
    Reap(&status);
  }
  seconds_ = SecondsSince(born_);
  exit_code_ = started_ ? ExitCode(status) : kCannotRun;
  return exit_code_;
}

}  // namespace carmba
