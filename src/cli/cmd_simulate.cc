// `carmba simulate --scene configs/scenes/NAME.yaml --out DIR`: renders a simulated X-ray scene
// (sim/xray_scene.h) or CT scene (ct/ct_simulate.h) into DIR with DIR/truth.json.
//
// Everything is written into a staging directory (beside DIR, or inside an existing DIR) and moved
// into place at the end, so an error leaves no partial output. An existing non-empty DIR is an
// error unless --force, which replaces its contents (the whole directory: a simulation is one
// consistent set of images and truth).
#include <gflags/gflags.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <random>
#include <sstream>
#include <system_error>

#include "cli/command.h"
#include "cli/common_flags.h"
#include "ct/ct_simulate.h"
#include "geometry/random_vector.h"
#include "sim/xray_scene.h"
#include "util/file_util.h"
#include "util/random.h"
#include "util/yaml_reader.h"

DEFINE_string(scene, "", "Scene YAML file (configs/scenes/*.yaml), kind xray, ct or joint.");
// --out (output directory: images or the ct/ DICOM series, and truth.json), --seed (overrides
// an X-ray scene's noise seed) and --force (replace an existing non-empty --out) are shared:
// cli/common_flags.h.

namespace {

namespace fs = std::filesystem;

// A joint scene (configs/scenes/thesis_joint.yaml): a plate scene and an object scene seen by the
// SAME C-arm camera, and the object's CT, with one truth:
//   kind: joint
//   plate: thesis_calibration.yaml     # X-ray scene of the calibration plate  -> DIR/plate/
//   object: thesis_pose.yaml           # X-ray scene of the marker object      -> DIR/object/
//   ct: thesis_ct.yaml                 # CT scene of the object                -> DIR/ct/
//   object_picks: {sigma_px: 0.3, seed: 7}
// DIR/object/observations.csv holds the object views' marker centres (view, marker, u_px, v_px):
// the true projections plus Gaussian noise of sigma_px, standing in for the manual picking of the
// thesis (marker detection in object views is not built yet). DIR/truth.json: the camera, the
// object views' cam_from_object (object = the marker model's frame), the sub-scenes' files, every
// view's true intrinsics (view_intrinsics; they depend on the angles when the scenes have
// carm.flex) and the flex. DIR/views.csv: every view's C-arm angles (view, primary_deg,
// secondary_deg), for `angles: views.csv` in a problem.
carmba::Status SimulateJoint(carmba::YamlMap& scene,
                             const std::string& scene_path,
                             const std::string& tmp_dir,
                             bool override_seed,
                             nlohmann::json* truth) {
  using carmba::Status;
  using carmba::JoinPath;
  const std::string base = carmba::DirName(scene_path);
  std::string plate_file, object_file, ct_file, description;
  double pick_sigma = 0.3;
  int pick_seed = 1;
  scene.Get("description", &description);
  scene.Get("plate", &plate_file, true);
  scene.Get("object", &object_file, true);
  scene.Get("ct", &ct_file, true);
  carmba::YamlMap& picks = scene.Map("object_picks");
  picks.GetPositive("sigma_px", &pick_sigma);
  picks.Get("seed", &pick_seed);
  CARMBA_RETURN_IF_ERROR(scene.Finish());
  auto plate = carmba::sim::LoadXrayScene(JoinPath(base, plate_file));
  if (!plate.ok()) return plate.status();
  auto object = carmba::sim::LoadXrayScene(JoinPath(base, object_file));
  if (!object.ok()) return object.status();
  if (plate->object_kind != "plate") {
    return Status::Error(scene_path + ": key 'plate': " + plate_file + " is not a plate scene");
  }
  if (object->object_kind != "markers") {
    return Status::Error(scene_path + ": key 'object': " + object_file + " is not a marker scene");
  }
  const auto& pf = plate->flex;
  const auto& of = object->flex;
  const bool same_flex =
      pf.cx_primary_px == of.cx_primary_px && pf.cx_secondary_px == of.cx_secondary_px &&
      pf.cy_primary_px == of.cy_primary_px && pf.cy_secondary_px == of.cy_secondary_px &&
      pf.f_primary == of.f_primary && pf.f_secondary == of.f_secondary;
  if (plate->camera.params != object->camera.params ||
      plate->camera.width != object->camera.width ||
      plate->camera.height != object->camera.height || !same_flex) {
    return Status::Error(scene_path + ": the plate and object scenes must share one camera (" +
                         plate_file + " and " + object_file + " differ in camera: or carm.flex)");
  }
  if (override_seed) {
    carmba::sim::ReseedXrayScene(FLAGS_seed, &plate.value());
    carmba::sim::ReseedXrayScene(FLAGS_seed + 1, &object.value());
  }
  nlohmann::json tp, to, tc;
  const std::string plate_dir = JoinPath(tmp_dir, "plate"),
                    object_dir = JoinPath(tmp_dir, "object");
  CARMBA_RETURN_IF_ERROR(carmba::MakeDirs(plate_dir));
  CARMBA_RETURN_IF_ERROR(carmba::MakeDirs(object_dir));
  CARMBA_RETURN_IF_ERROR(carmba::sim::SimulateXrayScene(*plate, plate_dir, &tp));
  CARMBA_RETURN_IF_ERROR(carmba::sim::SimulateXrayScene(*object, object_dir, &to));
  CARMBA_RETURN_IF_ERROR(
      carmba::WriteFileAtomic(JoinPath(plate_dir, "truth.json"), tp.dump(2) + "\n"));
  CARMBA_RETURN_IF_ERROR(
      carmba::WriteFileAtomic(JoinPath(object_dir, "truth.json"), to.dump(2) + "\n"));
  carmba::YamlMap ct_scene = carmba::YamlMap::Load(JoinPath(base, ct_file));
  CARMBA_RETURN_IF_ERROR(ct_scene.status());
  std::string ct_kind;
  ct_scene.GetEnum("kind", {"ct"}, &ct_kind, true);
  CARMBA_RETURN_IF_ERROR(ct_scene.status());
  CARMBA_RETURN_IF_ERROR(carmba::SimulateCtScene(ct_scene, tmp_dir, &tc));
  CARMBA_RETURN_IF_ERROR(
      carmba::WriteFileAtomic(JoinPath(tmp_dir, "ct_truth.json"), tc.dump(2) + "\n"));
  // The picked marker centres of the object views.
  Rng rng(static_cast<uint64_t>(pick_seed) + (override_seed ? FLAGS_seed * 7919ULL : 0));
  std::normal_distribution<double> gauss(0.0, pick_sigma);
  std::ostringstream csv;
  csv << "# carmba simulate: true marker projections + Gaussian pick noise sigma " << pick_sigma
      << " px (seed " << pick_seed << ")\nview,marker,u_px,v_px\n";
  const auto& ids = to.at("object").at("sphere_ids");
  nlohmann::json views = nlohmann::json::array();
  for (const auto& v : to.at("views")) {
    const auto& px = v.at("centers_px");
    for (size_t k = 0; k < px.size(); ++k) {
      char line[160];
      const Eigen::Vector2d pick_noise = RandomVector<2>(gauss, rng);
      std::snprintf(line, sizeof line, "%s,%d,%.4f,%.4f\n", v.at("name").get<std::string>().c_str(),
                    ids.at(k).get<int>(), px.at(k).at(0).get<double>() + pick_noise[0],
                    px.at(k).at(1).get<double>() + pick_noise[1]);
      csv << line;
    }
    const auto& cfo = v.at("cam_from_object");
    views.push_back({{"id", v.at("name")}, {"rvec", cfo.at("rvec")}, {"t_mm", cfo.at("t_mm")}});
  }
  CARMBA_RETURN_IF_ERROR(
      carmba::WriteFileAtomic(JoinPath(object_dir, "observations.csv"), csv.str()));
  // Every view's C-arm angles (for problems with angle-dependent intrinsics: `angles: views.csv`)
  // and its true intrinsics (with carm.flex they differ from view to view).
  std::ostringstream angles;
  angles << "# carmba simulate: the C-arm angles of every plate and object view\n"
            "view,primary_deg,secondary_deg\n";
  nlohmann::json view_intrinsics = nlohmann::json::array();
  for (const nlohmann::json* tv : {&tp, &to}) {
    for (const auto& v : tv->at("views")) {
      char line[160];
      std::snprintf(line, sizeof line, "%s,%.6g,%.6g\n", v.at("name").get<std::string>().c_str(),
                    v.at("primary_deg").get<double>(), v.at("secondary_deg").get<double>());
      angles << line;
      view_intrinsics.push_back({{"id", v.at("name")},
                                 {"primary_deg", v.at("primary_deg")},
                                 {"secondary_deg", v.at("secondary_deg")},
                                 {"camera", v.at("intrinsics")}});
    }
  }
  CARMBA_RETURN_IF_ERROR(carmba::WriteFileAtomic(JoinPath(tmp_dir, "views.csv"), angles.str()));
  (*truth)["kind"] = "joint";
  (*truth)["description"] = description;
  (*truth)["camera"] = carmba::CameraToJson(plate->camera);
  (*truth)["object_views"] = views;
  (*truth)["view_intrinsics"] = view_intrinsics;
  (*truth)["flex"] = {{"cx_primary_px", pf.cx_primary_px}, {"cx_secondary_px", pf.cx_secondary_px},
                      {"cy_primary_px", pf.cy_primary_px}, {"cy_secondary_px", pf.cy_secondary_px},
                      {"f_primary", pf.f_primary}, {"f_secondary", pf.f_secondary},
                      {"model", "camera/carm_flex.h"}};
  (*truth)["object_picks"] = {{"sigma_px", pick_sigma}, {"seed", pick_seed}};
  (*truth)["files"] = {{"plate", "plate/truth.json"}, {"object", "object/truth.json"},
                       {"ct", "ct_truth.json"}, {"ct_series", "ct/"}};
  (*truth)["ct_markers"] = tc.at("markers");
  return Status::Ok();
}

carmba::Status Simulate(const std::string& scene_path,
                        const std::string& tmp_dir,
                        bool override_seed) {
  using carmba::Status;
  carmba::YamlMap scene = carmba::YamlMap::Load(scene_path);
  if (!scene.status().ok()) return scene.status();
  std::string kind;
  scene.GetEnum("kind", {"xray", "ct", "joint"}, &kind, true);
  if (!scene.status().ok()) return scene.status();
  CARMBA_RETURN_IF_ERROR(carmba::MakeDirs(tmp_dir));
  nlohmann::json truth;
  truth["scene"] = scene_path;
  if (kind == "joint") {
    CARMBA_RETURN_IF_ERROR(SimulateJoint(scene, scene_path, tmp_dir, override_seed, &truth));
  } else if (kind == "ct") {
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
  // --scene and --out are required (checked before this runs: cli/command.h).
  fs::path out = fs::path(FLAGS_out).lexically_normal();
  if (out.filename().empty()) out = out.parent_path();  // trailing '/'
  if (const carmba::Status s = carmba::cli::CheckOutDir(); !s.ok()) {
    return carmba::cli::Fail(cmd, s);
  }
  carmba::cli::Step(cmd, "simulating " + FLAGS_scene);
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

CARMBA_COMMAND_FLAGS(simulate, "out,seed,force");
CARMBA_REQUIRED_FLAGS(simulate, "scene,out");
CARMBA_REGISTER_COMMAND(simulate,
                        "Simulate C-arm X-ray images or a CT series with ground truth.",
                        RunSimulate);
