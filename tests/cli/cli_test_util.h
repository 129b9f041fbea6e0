// Helpers for end-to-end tests that run the built `carmba` command.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "synthetic/synthetic_views.h"
#include "detect/observations.h"
#include "scratch.h"

namespace carmba::test {

// The source tree (configs/, problems/, data/, src/docs/).
inline const std::string kSource = CARMBA_SOURCE_DIR;

struct CommandResult {
  int exit_code = -1;
  std::string out;  // stdout
  std::string err;  // stderr
};

// Runs `carmba <args>` (args are passed to the shell as written), capturing stdout and stderr,
// with `env` ("NAME=value ...", may be empty) added to the environment.
inline CommandResult RunCarmbaWithEnv(const std::string& env, const std::string& args) {
  const ScratchDir tmp("cli_run");
  const std::string cmd = (env.empty() ? "" : "env " + env + " ") + std::string(CARMBA_BIN) +
                          " " + args + " >" + tmp.File("out") + " 2>" + tmp.File("err");
  const int status = std::system(cmd.c_str());
  CommandResult r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  auto slurp = [](const std::string& p) {
    std::ifstream in(p);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  };
  r.out = slurp(tmp.File("out"));
  r.err = slurp(tmp.File("err"));
  return r;
}

inline CommandResult RunCarmba(const std::string& args) { return RunCarmbaWithEnv("", args); }

// The text of a file ("" if unreadable) and a JSON file parsed (a discarded value, not an
// exception, when it is missing or malformed: check is_object()).
inline std::string ReadTextFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}
inline nlohmann::json ReadJsonFile(const std::string& path) {
  return nlohmann::json::parse(ReadTextFile(path), nullptr, /*allow_exceptions=*/false);
}

// The output of `carmba simulate --scene configs/scenes/<scene>.yaml` (a joint scene NAME_joint
// with its CT fiducials in fiducials.csv), to be read only. Under ctest it is the fixture
// cli_scenes's (tests/cli/simulate_scenes.sh, run once before the CLI tests; CARMBA_TEST_SCENES
// names its directory) when that has the scene; otherwise the same script renders it once per
// process into a scratch directory. Returns the directory, or "" with the reason in *error.
inline std::string SimulatedScene(const std::string& scene, std::string* error) {
  const char* fixture = std::getenv("CARMBA_TEST_SCENES");
  if (fixture != nullptr) {
    const std::string dir = std::string(fixture) + "/" + scene;
    if (std::filesystem::exists(dir + "/truth.json")) return dir;
  }
  static const ScratchDir rendered("scenes");
  const std::string dir = rendered.File(scene);
  if (std::filesystem::exists(dir + "/truth.json")) return dir;
  const ScratchDir log("simulate_scenes");
  const std::string cmd = "bash " + kSource + "/tests/cli/simulate_scenes.sh " + CARMBA_BIN + " " +
                          kSource + " " + rendered.path() + " " + scene + " >/dev/null 2>" +
                          log.File("err");
  if (std::system(cmd.c_str()) != 0) {
    *error = "simulate " + scene + ": " + ReadTextFile(log.File("err"));
    return "";
  }
  return dir;
}

// SimulatedScene(scene) seen at `path` (a symbolic link), for tests that keep their inputs in
// their own directory. Returns the failure's reason, or "" on success.
inline std::string LinkSimulatedScene(const std::string& scene, const std::string& path) {
  std::string error;
  const std::string dir = SimulatedScene(scene, &error);
  if (dir.empty()) return error;
  std::error_code ec;
  std::filesystem::create_directory_symlink(dir, path, ec);
  return ec ? "link " + path + " -> " + dir + ": " + ec.message() : "";
}

// A shipped joint scene (configs/scenes/NAME) with its CT fiducials in scene/fiducials.csv, seen
// at `scene` (a link to SimulatedScene's directory), to be read only. Returns the failure's
// reason, or "" on success.
inline std::string SimulateJointScene(const std::string& scene_yaml, const std::string& scene) {
  return LinkSimulatedScene(std::filesystem::path(scene_yaml).stem().string(), scene);
}

// Simulated plate images (configs/scenes/thesis_calibration.yaml) at dir/plate and a simulated
// CT series (thesis_ct.yaml) at dir/ct (SimulatedScene, linked): shared inputs of the CLI
// fixtures, read only. Returns the failure's reason, or "" on success.
inline std::string SimulatePlateAndCt(const ScratchDir& dir) {
  const std::string err = LinkSimulatedScene("thesis_calibration", dir.File("plate"));
  return err.empty() ? LinkSimulatedScene("thesis_ct", dir.File("ct")) : err;
}

// Synthetic observations of the default 5 x 5 plate by a thesis-like camera (408 x 408 px), as
// observations.csv at `path` (synthetic/synthetic_views.h defaults): input for a quick calibrate.
inline bool WriteSyntheticGridObservations(const std::string& path) {
  SyntheticViewsOptions so;
  GridSpec g;
  const auto obs = MakeSyntheticViews({2061, 2255, 204, 205, 0, 0, 0, 0, 0}, 408, 408, g, so);
  return WriteObservationsCsv(obs, path).ok();
}

inline int CountLines(const std::string& s) {
  int n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

}  // namespace carmba::test
