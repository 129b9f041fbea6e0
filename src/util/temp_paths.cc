#include "util/temp_paths.h"

#include <dirent.h>
#include <fcntl.h>
#include <limits.h>
#include <pthread.h>
#include <signal.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <system_error>

namespace carmba {
namespace {

enum SlotState : int { kFree = 0, kBusy = 1, kActive = 2 };

struct Slot {
  std::atomic<int> state{kFree};
  char path[PATH_MAX];
};

Slot g_slots[kMaxTempPaths];

struct ChildSlot {
  std::atomic<int> state{kFree};
  pid_t pid = -1;
};

ChildSlot g_children[kMaxChildProcesses];

// Threads inside a SignalCriticalSection (they block SIGINT / SIGTERM meanwhile).
std::atomic<int> g_critical_sections{0};

// Waits (at most 5 s) until no thread is between making a path or child and registering it.
// Async-signal-safe (nanosleep).
void WaitForCriticalSections() {
  const timespec one_ms{0, 1000000};
  for (int i = 0; i < 5000 && g_critical_sections.load() > 0; ++i) ::nanosleep(&one_ms, nullptr);
}

// Kills and reaps the registered children. Async-signal-safe (kill, waitpid).
void KillRegisteredChildren() {
  for (ChildSlot& c : g_children) {
    if (c.state.load() != kActive) continue;
    ::kill(c.pid, SIGKILL);
    while (::waitpid(c.pid, nullptr, 0) < 0 && errno == EINTR) {
    }
  }
}

// getdents64's record (the glibc wrapper is not async-signal-safe; the system call is).
struct LinuxDirent64 {
  uint64_t d_ino;
  int64_t d_off;
  unsigned short d_reclen;
  unsigned char d_type;
  char d_name[1];
};

bool IsDotOrDotDot(const char* n) {
  return n[0] == '.' && (n[1] == 0 || (n[1] == '.' && n[2] == 0));
}

// Removes `name` in the directory `dirfd` and, for a directory, everything in it (depth-limited:
// carmba's temporary trees are two levels deep). Async-signal-safe.
void RemoveAt(int dirfd, const char* name, int depth) {
  if (::unlinkat(dirfd, name, 0) == 0 || errno == ENOENT) return;
  if (depth > 32) return;
  const int fd = ::openat(dirfd, name, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
  if (fd < 0) return;
  alignas(8) char buf[4096];
  // Entries are removed batch by batch from the start until a pass removes nothing.
  for (int pass = 0; pass < 1000; ++pass) {
    bool removed = false;
    ::lseek(fd, 0, SEEK_SET);
    for (;;) {
      const long n = ::syscall(SYS_getdents64, fd, buf, sizeof(buf));
      if (n <= 0) break;
      for (long at = 0; at < n;) {
        const auto* d = reinterpret_cast<const LinuxDirent64*>(buf + at);
        if (!IsDotOrDotDot(d->d_name)) {
          RemoveAt(fd, d->d_name, depth + 1);
          removed = true;
        }
        at += d->d_reclen;
      }
    }
    if (!removed) break;
  }
  ::close(fd);
  ::unlinkat(dirfd, name, AT_REMOVEDIR);
}

void OnSignal(int sig) {
  const int saved = errno;
  WaitForCriticalSections();
  RemoveRegisteredTempPaths();
  errno = saved;
  ::signal(sig, SIG_DFL);
  ::raise(sig);  // delivered when the handler returns (the signal is blocked while it runs)
}

}  // namespace

int RegisterTempPath(const std::string& path) {
  std::error_code ec;
  const std::string abs = std::filesystem::absolute(path, ec).lexically_normal().string();
  if (ec || abs.size() + 1 > PATH_MAX) return -1;
  for (int i = 0; i < kMaxTempPaths; ++i) {
    int expected = kFree;
    if (g_slots[i].state.compare_exchange_strong(expected, kBusy)) {
      std::memcpy(g_slots[i].path, abs.c_str(), abs.size() + 1);
      g_slots[i].state.store(kActive);
      return i;
    }
  }
  return -1;
}

void UnregisterTempPath(int slot) {
  if (slot < 0 || slot >= kMaxTempPaths) return;
  g_slots[slot].state.store(kBusy);
  g_slots[slot].path[0] = 0;
  g_slots[slot].state.store(kFree);
}

int NumRegisteredTempPaths() {
  int n = 0;
  for (const Slot& s : g_slots) n += s.state.load() == kActive;
  return n;
}

int RegisterChildProcess(pid_t pid) {
  if (pid <= 0) return -1;
  for (int i = 0; i < kMaxChildProcesses; ++i) {
    int expected = kFree;
    if (g_children[i].state.compare_exchange_strong(expected, kBusy)) {
      g_children[i].pid = pid;
      g_children[i].state.store(kActive);
      return i;
    }
  }
  return -1;
}

void UnregisterChildProcess(int slot) {
  if (slot < 0 || slot >= kMaxChildProcesses) return;
  g_children[slot].state.store(kBusy);
  g_children[slot].pid = -1;
  g_children[slot].state.store(kFree);
}

int NumRegisteredChildProcesses() {
  int n = 0;
  for (const ChildSlot& c : g_children) n += c.state.load() == kActive;
  return n;
}

void RemoveRegisteredTempPaths() {
  KillRegisteredChildren();
  for (Slot& s : g_slots) {
    if (s.state.load() == kActive) RemoveAt(AT_FDCWD, s.path, 0);
  }
}

void InstallTempPathCleanup() {
  struct sigaction sa;
  std::memset(&sa, 0, sizeof(sa));
  sa.sa_handler = OnSignal;
  sigemptyset(&sa.sa_mask);
  sigaddset(&sa.sa_mask, SIGINT);
  sigaddset(&sa.sa_mask, SIGTERM);
  for (int sig : {SIGINT, SIGTERM}) {
    struct sigaction old;
    // A signal the parent set to be ignored (nohup, a background job's SIGINT) stays ignored.
    if (::sigaction(sig, nullptr, &old) == 0 && old.sa_handler == SIG_IGN) continue;
    ::sigaction(sig, &sa, nullptr);
  }
}

SignalCriticalSection::SignalCriticalSection() {
  sigset_t block;
  sigemptyset(&block);
  sigaddset(&block, SIGINT);
  sigaddset(&block, SIGTERM);
  ::pthread_sigmask(SIG_BLOCK, &block, &previous_mask_);
  g_critical_sections.fetch_add(1);
}

SignalCriticalSection::~SignalCriticalSection() {
  g_critical_sections.fetch_sub(1);
  ::pthread_sigmask(SIG_SETMASK, &previous_mask_, nullptr);  // a held-back signal arrives now
}

ScopedTempPath::ScopedTempPath(std::string path)
    : path_(std::move(path)), slot_(RegisterTempPath(path_)) {}

ScopedTempPath::~ScopedTempPath() {
  if (!released_) {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  UnregisterTempPath(slot_);
}

void ScopedTempPath::Release() {
  released_ = true;
  UnregisterTempPath(slot_);
  slot_ = -1;
}

}  // namespace carmba
