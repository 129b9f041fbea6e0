// Temporary files and directories removed on SIGINT and SIGTERM.
//
// Every temporary path carmba creates beside or inside an output (WriteFileAtomic's
// `FILE.tmp.PID`, StagedOutputDir's `DIR.tmp.PID` / `DIR/.carmba-tmp.PID`, the mrcal cross-check's
// `OUT.mrcal.tmp.PID/`, the plot scripts' directory) is registered here while it exists. The
// `carmba` command installs a handler (InstallTempPathCleanup) that, on SIGINT or SIGTERM, removes
// every registered path (recursively), restores the default action and re-raises the signal, so
// the exit status still says "killed by SIGTERM" and nothing `*.tmp*` is left behind.
//
// The handler only uses async-signal-safe system calls (openat, getdents64, unlinkat); the
// registry is a fixed table of slots claimed with atomics, so a signal arriving while another
// thread registers a path never deadlocks. A path registered when the table is full (more than
// kMaxTempPaths at once) is not removed by the handler (it is still removed by its owner).
//
// Child processes (the Python interpreters of the plots and the mrcal cross-check,
// util/python_worker.h) are registered the same way: the handler kills them (SIGKILL) and reaps
// them before it removes the paths, so no interpreter outlives a carmba killed by SIGTERM or
// SIGINT, nor writes into a directory being removed.
#pragma once

#include <signal.h>
#include <sys/types.h>

#include <string>

namespace carmba {

inline constexpr int kMaxTempPaths = 256;

// Registers `path` (made absolute); returns its slot (-1 when the table is full or the path is
// longer than PATH_MAX). UnregisterTempPath(-1) is a no-op.
int RegisterTempPath(const std::string& path);
void UnregisterTempPath(int slot);
// The paths registered now (for tests).
int NumRegisteredTempPaths();

inline constexpr int kMaxChildProcesses = 32;
// Registers a child process to be killed on SIGINT / SIGTERM; returns its slot (-1 when the table
// is full). The owner unregisters it before reaping it (waitpid), so a recycled pid is never hit.
int RegisterChildProcess(pid_t pid);
void UnregisterChildProcess(int slot);
int NumRegisteredChildProcesses();

// Installs the SIGINT / SIGTERM handler (idempotent). Library code never calls it: only main().
void InstallTempPathCleanup();
// What the handler does before re-raising (for tests): kills and reaps every registered child
// process, then removes every registered path.
void RemoveRegisteredTempPaths();

// The moment between making a temporary path or a child process and registering it. While it
// lasts, SIGINT and SIGTERM are blocked in this thread, and the handler, should another thread
// take the signal, waits for it to end (at most 5 s). Without it a signal arriving there found the
// new path or child unregistered: glibc's posix_spawn holds signals back until the child has
// started, so a SIGTERM sent meanwhile arrived exactly between the spawn and the registration, and
// the interpreter outlived carmba (6 of 90 runs of TempPaths.SigtermDuringTheMrcalStep... under
// load). Scopes nest; the previous signal mask is restored at the end.
class SignalCriticalSection {
 public:
  SignalCriticalSection();
  ~SignalCriticalSection();
  SignalCriticalSection(const SignalCriticalSection&) = delete;
  SignalCriticalSection& operator=(const SignalCriticalSection&) = delete;

 private:
  sigset_t previous_mask_;
};

// Registration for a scope (the owner removes or renames the path itself; the handler removes it
// on a signal until the scope ends).
class TempPathRegistration {
 public:
  explicit TempPathRegistration(const std::string& path) : slot_(RegisterTempPath(path)) {}
  ~TempPathRegistration() { UnregisterTempPath(slot_); }
  TempPathRegistration(const TempPathRegistration&) = delete;
  TempPathRegistration& operator=(const TempPathRegistration&) = delete;

 private:
  int slot_;
};

// A temporary path owned by a scope: registered on construction, removed (recursively) and
// unregistered on destruction unless Release() was called (it was renamed into place).
class ScopedTempPath {
 public:
  explicit ScopedTempPath(std::string path);
  ~ScopedTempPath();
  ScopedTempPath(const ScopedTempPath&) = delete;
  ScopedTempPath& operator=(const ScopedTempPath&) = delete;
  const std::string& path() const { return path_; }
  // Keeps the path on destruction (and stops the handler from removing it).
  void Release();

 private:
  std::string path_;
  int slot_ = -1;
  bool released_ = false;
};

}  // namespace carmba
