// A Python interpreter started before its script is known, so that its imports (matplotlib about
// 1 s, mrcal with numpy about 1 s) overlap the caller's own work: start the worker early, hand it
// the script once its input is ready (Start returns at once), and Wait at the end. Two workers
// run concurrently (e.g. the report plots and the mrcal cross-check).
//
// The interpreter runs a small bootstrap (`python -c`): it executes `preload` (errors ignored: the
// script reports a missing module itself, as before), reads one job line from a socket (script,
// arguments, stdout and stderr files), redirects its stdout and stderr there and runs the script
// as __main__ (runpy, sys.argv and sys.path[0] as `python SCRIPT ARGS...` sets them). The exit
// code is what the script's sys.exit gives (1 for an uncaught exception, after the traceback).
// Without a job (the worker is destroyed first) the interpreter is killed. While it runs it is
// registered with util/temp_paths.h, so a carmba killed by SIGINT or SIGTERM kills it too.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <string>
#include <vector>

namespace carmba {

class PythonWorker {
 public:
  // Exit codes Wait returns besides the script's own (the shell's conventions).
  static constexpr int kTimedOut = 124;   // killed after timeout_s (as timeout(1))
  static constexpr int kCannotRun = 127;  // the interpreter could not be started

  // Starts `python` (a path, or a name looked up in PATH) running `preload`, e.g.
  // "import numpy, mrcal". Never fails: a worker that cannot start reports kCannotRun from Wait.
  PythonWorker(const std::string& python, const std::string& preload);
  ~PythonWorker();  // kills and reaps an interpreter that was not waited for
  PythonWorker(const PythonWorker&) = delete;
  PythonWorker& operator=(const PythonWorker&) = delete;

  // Hands the worker its one job (an empty stdout_path or stderr_path: carmba's own). Returns false
  // (then Wait gives kCannotRun) when the worker is not running or already has a job.
  bool Start(const std::string& script_path,
             const std::vector<std::string>& args,
             const std::string& stdout_path,
             const std::string& stderr_path);
  // Waits for the script (at most timeout_s seconds after Start; 0 = no limit, then kill it and
  // return kTimedOut) and returns its exit code. Idempotent.
  int Wait(int timeout_s = 0);

  // The interpreter's wall time from the worker's start to the end of Wait (seconds).
  double seconds() const { return seconds_; }

 private:
  void Reap(int* status);  // unregisters the child, then waitpid

  std::string python_;
  pid_t pid_ = -1;
  int child_slot_ = -1;  // util/temp_paths.h: killed on SIGINT / SIGTERM while it runs
  int socket_ = -1;  // our end of the job socket
  bool started_ = false;
  bool waited_ = false;
  int exit_code_ = kCannotRun;
  double seconds_ = 0;
  std::chrono::steady_clock::time_point born_, job_sent_;
};

}  // namespace carmba
