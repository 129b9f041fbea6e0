#include "util/accepted_keys.h"

#include <atomic>
#include <cstdlib>
#include <fstream>
#include <mutex>

namespace carmba {
namespace {

std::atomic<bool> g_enabled{false};

std::mutex& Mu() {
  static std::mutex mu;
  return mu;
}

std::map<std::string, std::set<std::string>>& Keys() {
  static auto* keys = new std::map<std::string, std::set<std::string>>;  // outlives atexit
  return *keys;
}

void WriteAtExit() {
  const char* out = std::getenv("CARMBA_ACCEPTED_KEYS");
  if (out == nullptr || *out == '\0') return;
  std::ofstream f(out, std::ios::app);
  for (const auto& [file, keys] : AcceptedKeys()) {
    for (const auto& k : keys) f << file << '\t' << k << '\n';
  }
}

// CARMBA_ACCEPTED_KEYS switches recording on for the whole process.
const bool kFromEnvironment = [] {
  const char* out = std::getenv("CARMBA_ACCEPTED_KEYS");
  if (out == nullptr || *out == '\0') return false;
  g_enabled = true;
  std::atexit(WriteAtExit);
  return true;
}();

}  // namespace

void EnableAcceptedKeyRecording() { g_enabled = true; }

bool AcceptedKeyRecordingEnabled() { return g_enabled; }

void RecordAcceptedKey(const std::string& file, const std::string& key) {
  if (!g_enabled) return;
  std::lock_guard<std::mutex> lock(Mu());
  Keys()[file].insert(key);
}

std::map<std::string, std::set<std::string>> AcceptedKeys() {
  std::lock_guard<std::mutex> lock(Mu());
  return Keys();
}

void ClearAcceptedKeys() {
  std::lock_guard<std::mutex> lock(Mu());
  Keys().clear();
}

}  // namespace carmba
