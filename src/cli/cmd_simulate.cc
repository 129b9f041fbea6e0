// `carmba simulate --scene configs/scenes/NAME.yaml --out DIR`: renders a simulated X-ray scene
// (sim/xray_scene.h) or CT scene (ct/ct_simulate.h) into DIR with DIR/truth.json.
//
// Everything is written into a staging directory (beside DIR, or inside an existing DIR) and moved
// into place at the end, so an error leaves no partial output. An existing non-empty DIR is an
// error unless --overwrite, which replaces its contents.
#include <gflags/gflags.h>
#include <unistd.h>

#include <filesystem>
#include <iostream>
#include <system_error>

#include "cli/command.h"
#include "cli/common_flags.h"
#include "ct/ct_simulate.h"
#include "sim/xray_scene.h"
#include "util/file_util.h"
#include "util/yaml_reader.h"

DEFINE_string(scene, "", "Scene YAML file (configs/scenes/*.yaml), kind xray or ct.");
// --out (output directory: images or the ct/ DICOM series, and truth.json) and --seed (overrides
// an X-ray scene's noise seed) are shared: cli/common_flags.h.
DEFINE_bool(overwrite, false, "Replace an existing non-empty output directory.");

namespace {

namespace fs = std::filesystem;

carmba::Status Simulate(const std::string& scene_path,
                        const std::string& tmp_dir,
                        bool override_seed) {
  using carmba::Status;
  carmba::YamlMap scene = carmba::YamlMap::Load(scene_path);
  if (!scene.status().ok()) return scene.status();
  std::string kind;
  scene.GetEnum("kind", {"xray", "ct"}, &kind, true);
  if (!scene.status().ok()) return scene.status();
  CARMBA_RETURN_IF_ERROR(carmba::MakeDirs(tmp_dir));
  nlohmann::json truth;
  truth["scene"] = scene_path;
  if (kind == "ct") {
    if (override_seed) {
      return Status::Error(scene_path +
                           ": --seed applies to X-ray scenes; set the CT scene's seed");
    }
    CARMBA_RETURN_IF_ERROR(carmba::SimulateCtScene(scene, tmp_dir, &truth));
    truth["kind"] = "ct";
  } else {
    carmba::sim::XrayScene xray;
    CARMBA_RETURN_IF_ERROR(carmba::sim::ParseXrayScene(scene, &xray));
    if (override_seed) carmba::sim::ReseedXrayScene(FLAGS_seed, &xray);
    CARMBA_RETURN_IF_ERROR(carmba::sim::SimulateXrayScene(xray, tmp_dir, &truth));
  }
  return carmba::WriteFileAtomic(carmba::JoinPath(tmp_dir, "truth.json"), truth.dump(2) + "\n");
}

int RunSimulate() {
  const std::string cmd = "simulate";
  if (FLAGS_scene.empty()) return carmba::cli::Fail(cmd, "--scene is required");
  if (FLAGS_out.empty()) return carmba::cli::Fail(cmd, "--out is required");
  fs::path out = fs::path(FLAGS_out).lexically_normal();
  if (out.filename().empty()) out = out.parent_path();  // trailing '/'
  {
    const carmba::Status s = carmba::CheckOutputDir(out.string(), "--out");
    if (!s.ok()) return carmba::cli::Fail(cmd, s);
  }
  std::error_code ec;
  const bool exists = fs::exists(out, ec);
  const bool non_empty = exists && !fs::is_empty(out, ec);
  if (non_empty && !FLAGS_overwrite) {
    return carmba::cli::Fail(cmd,
                             out.string() +
                                 ": output directory exists and is not empty "
                                 "(use --overwrite to replace it)");
  }
  // Staged beside DIR when it does not exist, inside it when it does (util/file_util.h), so that
  // the final renames never cross file systems (DIR may be a mount point).
  carmba::StagedOutputDir staged(out.string());
  carmba::Status status = staged.Begin();
  const bool override_seed = !gflags::GetCommandLineFlagInfoOrDie("seed").is_default;
  if (status.ok()) status = Simulate(FLAGS_scene, staged.path(), override_seed);
  if (status.ok()) status = staged.Commit(/*replace_all=*/true);
  if (!status.ok()) return carmba::cli::Fail(cmd, status);
  std::cout << "wrote " << out.string() << " (truth.json)\n";
  return 0;
}

}  // namespace

CARMBA_COMMAND_FLAGS(simulate, "out,seed");
CARMBA_REGISTER_COMMAND(simulate,
                        "Simulate C-arm X-ray images or a CT series with ground truth.",
                        RunSimulate);
