#include "study/pose_study.h"

#include <cmath>
#include <map>
#include <memory>
#include <mutex>
#include <random>
#include <set>

#include "analysis/flex_models.h"
#include "ba/quantities.h"
#include "ba/view_intrinsics.h"
#include "calib/calibrate.h"
#include "camera/camera_model.h"
#include "geometry/random_vector.h"
#include "geometry/rotation.h"
#include "joint/joint_solver.h"
#include "problem/pose_solver.h"
#include "synthetic/synthetic_flex.h"
#include "synthetic/synthetic_joint.h"
#include "synthetic/synthetic_pose.h"
#include "synthetic/synthetic_views.h"
#include "util/file_util.h"
#include "util/format.h"
#include "util/plausible.h"
#include "util/random.h"

namespace carmba {
namespace {

// Gaussian draws (Box-Muller on a 64-bit Mersenne twister: the same numbers on every standard
// library, unlike std::normal_distribution).
double Gaussian(Rng& rng) {
  const double u1 = (static_cast<double>(rng() >> 11) + 0.5) * 0x1.0p-53;
  const double u2 = (static_cast<double>(rng() >> 11) + 0.5) * 0x1.0p-53;
  return std::sqrt(-2 * std::log(u1)) * std::cos(2 * kPi * u2);
}

const std::set<std::string>& KnownSweeps() {
  static const std::set<std::string> k = {"pixel_noise_px", "ct_noise_mm", "num_views", "k1"};
  return k;
}

// Strict reading of a JSON mapping (the `synthetic` and `options` entries of a study file).
class JsonMap {
 public:
  JsonMap(const nlohmann::json& j, std::string where) : j_(j), where_(std::move(where)) {}
  const nlohmann::json* Find(const std::string& key) {
    known_.insert(key);
    if (!j_.is_object() || !j_.contains(key) || j_[key].is_null()) return nullptr;
    return &j_[key];
  }
  void Fail(const std::string& key, const std::string& what) {
    if (status_.ok()) status_ = Status::Error(where_ + "." + key + ": " + what);
  }
  // A number, within `range` (util/plausible.h) when given.
  void Number(const std::string& key, double* out, const PlausibleRange* range = nullptr) {
    const nlohmann::json* v = Find(key);
    if (!v) return;
    if (!v->is_number() || !std::isfinite(v->get<double>())) return Fail(key, "expected a number");
    if (range && !InRange(v->get<double>(), *range)) {
      return Fail(key, "expected " + FormatRange(*range) + ", got " +
                           FormatCompact(v->get<double>()));
    }
    *out = v->get<double>();
  }
  void Vector3(const std::string& key, Eigen::Vector3d* out) {
    const nlohmann::json* v = Find(key);
    if (!v) return;
    if (!v->is_array() || v->size() != 3) return Fail(key, "expected a list of 3 numbers");
    for (int i = 0; i < 3; ++i) {
      if (!(*v)[i].is_number()) return Fail(key, "expected a list of 3 numbers");
      (*out)[i] = (*v)[i].get<double>();
    }
  }
  void Numbers(const std::string& key, std::vector<double>* out) {
    const nlohmann::json* v = Find(key);
    if (!v) return;
    if (!v->is_array() || v->empty()) return Fail(key, "expected a non-empty list of numbers");
    out->clear();
    for (const auto& e : *v) {
      if (!e.is_number()) return Fail(key, "expected a non-empty list of numbers");
      out->push_back(e.get<double>());
    }
  }
  void String(const std::string& key, std::string* out) {
    const nlohmann::json* v = Find(key);
    if (!v) return;
    if (!v->is_string()) return Fail(key, "expected a string");
    *out = v->get<std::string>();
  }
  Status Finish() {
    if (!status_.ok()) return status_;
    if (j_.is_object()) {
      for (const auto& kv : j_.items()) {
        if (!known_.count(kv.key())) {
          std::string list;
          for (const auto& k : known_) list += (list.empty() ? "" : ", ") + k;
          return Status::Error(where_ + ": unknown key '" + kv.key() + "' (known keys: " + list +
                               ")");
        }
      }
    }
    return status_;
  }

 private:
  const nlohmann::json& j_;
  std::string where_;
  std::set<std::string> known_;
  Status status_;
};

struct SyntheticEntry {
  SyntheticPoseSpec spec;
  double sigma_px = 0.5;
  double sigma_ct_mm = 0.1;
};

StatusOr<SyntheticEntry> ParseSynthetic(const StudyProblem& p) {
  const std::string where = "problem '" + p.name + "': synthetic";
  SyntheticEntry e;
  JsonMap m(p.synthetic, where);
  std::string kind = "pose";
  m.String("kind", &kind);
  std::string camera_file;
  m.String("camera", &camera_file);
  if (camera_file.empty()) m.Fail("camera", "missing, expected the path of a camera.json");
  if (const nlohmann::json* mk = m.Find("markers")) {
    if (mk->is_string() && mk->get<std::string>() == "thesis") {
      e.spec.markers = ThesisMarkers();
    } else if (mk->is_array()) {
      for (const auto& x : *mk) {
        if (!x.is_array() || x.size() != 3 || !x[0].is_number() || !x[1].is_number() ||
            !x[2].is_number()) {
          m.Fail("markers", "expected 'thesis' or a list of [x, y, z] (mm)");
          break;
        }
        e.spec.markers.emplace_back(x[0].get<double>(), x[1].get<double>(), x[2].get<double>());
      }
    } else {
      m.Fail("markers", "expected 'thesis' or a list of [x, y, z] (mm)");
    }
  } else {
    m.Fail("markers", "missing, expected 'thesis' or a list of [x, y, z] (mm)");
  }
  m.Numbers("view_angles_deg", &e.spec.view_angles_deg);
  m.Number("source_to_object_mm", &e.spec.source_to_object_mm, &plausible::kDistanceMm);
  m.Vector3("rotation_axis", &e.spec.rotation_axis);
  m.Vector3("base_rvec", &e.spec.base_rvec);
  if (const nlohmann::json* pairs = m.Find("pairs")) {
    e.spec.pairs.clear();
    for (const auto& x : *pairs) {
      if (!x.is_array() || x.size() != 2 || !x[0].is_number_integer() ||
          !x[1].is_number_integer()) {
        m.Fail("pairs", "expected a list of [view index, view index]");
        break;
      }
      e.spec.pairs.emplace_back(x[0].get<int>(), x[1].get<int>());
    }
  }
  m.Number("sigma_px", &e.sigma_px, &plausible::kPixelSigmaPx);
  m.Number("sigma_ct_mm", &e.sigma_ct_mm, &plausible::kCtSigmaMm);
  CARMBA_RETURN_IF_ERROR(m.Finish());
  if (kind != "pose") {
    return Status::Error(where + ".kind: expected pose or calibration, got '" + kind + "'");
  }
  if (e.spec.markers.size() < 4) return Status::Error(where + ".markers: expected >= 4 markers");
  if (!(e.spec.source_to_object_mm > 0)) {
    return Status::Error(where + ".source_to_object_mm: expected > 0");
  }
  if (!(e.spec.rotation_axis.norm() > 0)) {
    return Status::Error(where + ".rotation_axis: expected a non-zero vector");
  }
  const int nv = static_cast<int>(e.spec.view_angles_deg.size());
  for (const auto& [a, b] : e.spec.pairs) {
    if (a < 0 || b < 0 || a >= nv || b >= nv || a == b) {
      return Status::Error(where + ".pairs: expected two different view indices in [0, " +
                           std::to_string(nv) + ")");
    }
  }
  StatusOr<Camera> camera = ReadCameraJson(JoinPath(p.base_dir, camera_file));
  if (!camera.ok()) return camera.status().WithContext(where + ".camera");
  e.spec.camera = *camera;
  return e;
}

enum class MonteCarlo { kNone, kResimulate };

StatusOr<MonteCarlo> ParseProblemOptions(const StudyProblem& p) {
  MonteCarlo mc = MonteCarlo::kNone;
  if (p.options.is_null()) return mc;
  JsonMap m(p.options, "problem '" + p.name + "': options");
  std::string s = "none";
  m.String("monte_carlo", &s);
  CARMBA_RETURN_IF_ERROR(m.Finish());
  if (s == "resimulate") return MonteCarlo::kResimulate;
  if (s != "none") {
    return Status::Error("problem '" + p.name + "': options.monte_carlo: expected none or "
                         "resimulate, got '" + s + "'");
  }
  return mc;
}

// The reference solver for `resimulate`: SQPnP + bundle adjustment, analytic, dense.
SolverConfig ReferenceConfig() {
  SolverConfig c;
  c.name = "reference_sqpnp_ba";
  c.path = "<reference solver of carmba study>";
  c.initializer = Initializer::kSqpnp;
  c.num_threads = 1;
  return c;
}

// The truth of a resimulated problem: the reference solution of the measured data, markers in
// the problem frame (handedness as given), exact projections as observations.
StatusOr<Problem> MakeResimulationTruth(const Problem& measured) {
  StatusOr<PoseSolution> ref = SolvePoseProblem(measured, ReferenceConfig());
  if (!ref.ok()) return ref.status().WithContext("reference solve for resimulation");
  Problem p = measured;
  p.handedness = Handedness::kAsGiven;
  p.truth.markers.clear();
  p.truth.object_poses.clear();
  for (auto& m : p.fiducials) {
    m.p_in_object = MarkerInProblemFrame(measured, m);
    p.truth.markers[m.id] = m.p_in_object;
  }
  for (size_t v = 0; v < p.object_views.size(); ++v) {
    const Pose6& pose = ref->views[v].cam_from_object;
    p.truth.object_poses[p.object_views[v].id] = pose;
    for (auto& o : p.object_views[v].observations) {
      const Eigen::Vector3d& x = p.truth.markers.at(o.marker_id);
      if (!ProjectPoint(p.camera->params.data(), pose.data(), x.data(), o.uv_px.data())) {
        return Status::Error(measured.path + ": marker " + std::to_string(o.marker_id) +
                             " projects behind the source in the reference solution of view '" +
                             p.object_views[v].id + "'");
      }
    }
  }
  return p;
}

// Keeps the first `n` views and the validation pairs among them.
Status KeepViews(int n, Problem* p) {
  if (n < 1) return Status::Error("sweep num_views: expected an integer >= 1, got " +
                                  std::to_string(n));
  if (n > static_cast<int>(p->object_views.size())) {
    return Status::Error("sweep num_views = " + std::to_string(n) + ": the problem has only " +
                         std::to_string(p->object_views.size()) + " views");
  }
  p->object_views.resize(static_cast<size_t>(n));
  std::set<std::string> ids;
  for (const auto& v : p->object_views) ids.insert(v.id);
  std::vector<ValidationPair> kept;
  for (const auto& vp : p->validation) {
    if (ids.count(vp.a) && ids.count(vp.b)) kept.push_back(vp);
  }
  p->validation = kept;
  return Status::Ok();
}

template <typename T>
class OnceCache {
 public:
  template <typename F>
  std::shared_ptr<const StatusOr<T>> Get(const std::string& key, F make) {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = map_.find(key);
    if (it != map_.end()) return it->second;
    auto v = std::make_shared<const StatusOr<T>>(make());
    map_.emplace(key, v);
    return v;
  }

 private:
  std::mutex mutex_;
  std::map<std::string, std::shared_ptr<const StatusOr<T>>> map_;
};

double Rms(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return v.empty() ? std::nan("") : std::sqrt(s / static_cast<double>(v.size()));
}

// A synthetic calibration problem: a grid seen by a known camera from seeded random poses.
struct CalibrationEntry {
  Camera camera;  // the truth
  GridSpec grid;
  SyntheticViewsOptions views;
};

StatusOr<CalibrationEntry> ParseCalibrationSynthetic(const StudyProblem& p) {
  const std::string where = "problem '" + p.name + "': synthetic";
  CalibrationEntry e;
  JsonMap m(p.synthetic, where);
  std::string kind, camera_file, pattern = "circles";
  m.String("kind", &kind);
  m.String("camera", &camera_file);
  if (camera_file.empty()) m.Fail("camera", "missing, expected the path of a camera.json");
  double rows = e.grid.rows, cols = e.grid.cols, num_views = e.views.num_views;
  m.String("pattern", &pattern);
  m.Number("rows", &rows, &plausible::kGridRowsCols);
  m.Number("cols", &cols, &plausible::kGridRowsCols);
  m.Number("spacing_mm", &e.grid.spacing_mm, &plausible::kGridSpacingMm);
  m.Number("num_views", &num_views, &plausible::kViews);
  m.Number("noise_px", &e.views.noise_sigma_px);
  m.Number("min_tilt_deg", &e.views.min_tilt_deg, &plausible::kAngleDeg);
  m.Number("max_tilt_deg", &e.views.max_tilt_deg, &plausible::kAngleDeg);
  m.Number("distance_min_mm", &e.views.distance_min_mm, &plausible::kDistanceMm);
  m.Number("distance_max_mm", &e.views.distance_max_mm, &plausible::kDistanceMm);
  m.Number("max_offset_fraction", &e.views.max_offset_fraction);
  CARMBA_RETURN_IF_ERROR(m.Finish());
  StatusOr<GridPattern> gp = ParseGridPattern(pattern);
  if (!gp.ok()) return gp.status().WithContext(where + ".pattern");
  e.grid.pattern = *gp;
  e.grid.rows = static_cast<int>(rows);
  e.grid.cols = static_cast<int>(cols);
  e.views.num_views = static_cast<int>(num_views);
  std::string error;
  if (rows != e.grid.rows || cols != e.grid.cols || !e.grid.Check(&error)) {
    return Status::Error(where + ": grid: " + (error.empty() ? "rows, cols: expected integers"
                                                             : error));
  }
  if (num_views != e.views.num_views || e.views.num_views < 1) {
    return Status::Error(where + ".num_views: expected an integer >= 1");
  }
  StatusOr<Camera> camera = ReadCameraJson(JoinPath(p.base_dir, camera_file));
  if (!camera.ok()) return camera.status().WithContext(where + ".camera");
  e.camera = *camera;
  return e;
}

struct PoseStudyState {
  OnceCache<Problem> problems;            // measured problems, by file
  OnceCache<Problem> truths;              // resimulation truths, by file
  OnceCache<SolverConfig> configs;        // by file
  OnceCache<SyntheticEntry> synthetic;    // by base_dir|name
  OnceCache<CalibrationEntry> calibrations;      // by base_dir|name
  OnceCache<CalibrationOptions> calib_configs;   // by file
};

bool IsCalibration(const StudyProblem& p) {
  return p.synthetic.is_object() && p.synthetic.contains("kind") &&
         p.synthetic["kind"] == "calibration";
}

bool IsJoint(const StudyProblem& p) {
  return p.synthetic.is_object() && p.synthetic.contains("kind") && p.synthetic["kind"] == "joint";
}

// One run's record: convergence, errors against the truth, signed errors with their sigmas, values.
nlohmann::json RunRecordJson(bool converged,
                         const std::string& termination,
                         const nlohmann::json& errors,
                         const nlohmann::json& signed_errors,
                         const nlohmann::json& sigmas,
                         const nlohmann::json& values) {
  return {{"converged", converged},
          {"termination", termination},
          {"errors", errors},
          {"signed_errors", signed_errors},
          {"sigmas", sigmas},
          {"values", values}};
}

bool IsFlex(const StudyProblem& p) {
  return p.synthetic.is_object() && p.synthetic.contains("kind") && p.synthetic["kind"] == "flex";
}

// A synthetic FLEXING C-arm (synthetic/synthetic_flex.h) solved with one intrinsics model
// (synthetic.model: shared | per_group | smooth); the flex scaled by the sweep `flex_scale`
// (0: rigid, 1: CarmFlex::Typical()). Per-view intrinsics and object poses against the truth:
// signed errors with sigmas of the first calibrated and the first in-between object view, the
// mean NEES of the per-view intrinsics (fx fy cx cy; 4 if consistent) and of the object poses
// (6), the fraction of intrinsics within 3 sigma; with synthetic.select: 1 the recommended
// model of the held-out selection (values.recommended_*: 1 if it is that model).
StatusOr<nlohmann::json> RunFlex(PoseStudyState* state, const RunSpec& run) {
  for (const auto& kv : run.sweep) {
    if (kv.first != "flex_scale" && kv.first != "pixel_noise_px") {
      return Status::Error(
          "sweep variable '" + kv.first +
          "' is not understood by flex problems (known: flex_scale, pixel_noise_px)");
    }
  }
  const StudyProblem& sp = *run.problem;
  JsonMap m(sp.synthetic, "problem '" + sp.name + "': synthetic");
  std::string kind, model = "smooth";
  double select = 0, per = 6;
  m.String("kind", &kind);
  m.String("model", &model);
  m.Number("select", &select);
  m.Number("plate_views_per_orientation", &per, &plausible::kViews);
  ba::SyntheticFlexSpec spec;
  m.Number("sigma_plate_px", &spec.sigma_plate_px, &plausible::kPixelSigmaPx);
  m.Number("sigma_object_px", &spec.sigma_object_px, &plausible::kPixelSigmaPx);
  CARMBA_RETURN_IF_ERROR(m.Finish());
  analysis::IntrinsicsModel im;
  if (model == "shared") {
    im = analysis::IntrinsicsModel::kShared;
  } else if (model == "per_group") {
    im = analysis::IntrinsicsModel::kPerGroup;
  } else if (model == "smooth") {
    im = analysis::IntrinsicsModel::kSmooth;
  } else {
    return Status::Error("problem '" + sp.name + "': synthetic.model '" + model +
                         "' is unknown (shared, per_group, smooth)");
  }
  spec.plate_views_per_orientation = static_cast<int>(per);
  spec.sigma_object_px = run.SweepValue("pixel_noise_px", spec.sigma_object_px);
  const double scale = run.SweepValue("flex_scale", 1.0);
  const CarmFlex t = CarmFlex::Typical();
  spec.flex = {scale * t.cx_primary_px, scale * t.cx_secondary_px, scale * t.cy_primary_px,
               scale * t.cy_secondary_px, scale * t.f_primary, scale * t.f_secondary};
  auto config =
      state->configs.Get(run.config->file, [&] { return LoadSolverConfig(run.config->file); });
  if (!config->ok()) return config->status();
  ba::BaOptions options = config->value().ToBaOptions();
  options.num_threads = 1;
  const ba::SyntheticFlex sf = ba::MakeSyntheticFlex(spec, run.seed);
  ba::BaProblem p = sf.problem;
  CARMBA_RETURN_IF_ERROR(analysis::ApplyIntrinsicsModel(im, ba::SmoothBasis(), &p));
  auto r = ba::SolveBundleAdjustment(p, options);
  if (!r.ok()) return r.status();
  nlohmann::json signed_errors, sigmas, values, errors;
  double nees_cal = 0, nees_between = 0, nees_pose_at = 0, nees_pose_between = 0, within = 0;
  int n_cal = 0, n_between = 0, n_at = 0, n_comp = 0;
  bool first_at = true, first_between = true;
  static const char* const kPose[6] = {"rx_rad", "ry_rad", "rz_rad", "tx_mm", "ty_mm", "tz_mm"};
  for (size_t v = 0; v < p.views.size(); ++v) {
    const ba::ViewIntrinsics vi = ba::IntrinsicsOfView(p, *r, static_cast<int>(v));
    Eigen::Vector4d e;
    for (int i = 0; i < 4; ++i) {
      e[i] = vi.value[i] - sf.true_intrinsics[v][i];
      within += std::abs(e[i]) < 3 * std::sqrt(vi.covariance(i, i));
      ++n_comp;
    }
    const double nees = e.dot(vi.covariance.topLeftCorner<4, 4>().ldlt().solve(e));
    if (p.views[v].kind == ba::ViewKind::kPlate) {
      nees_cal += nees, ++n_cal;
      continue;
    }
    const Matrix6 C = r->ViewPoseCovariance(static_cast<int>(v));
    const Pose6 d = r->ViewPose(static_cast<int>(v)) - sf.true_poses[v];
    const double pose_nees = d.dot(C.ldlt().solve(d));
    const bool between = sf.between[v];
    if (between) {
      nees_between += nees, nees_pose_between += pose_nees, ++n_between;
    } else {
      nees_pose_at += pose_nees, ++n_at;
    }
    bool& first = between ? first_between : first_at;
    if (!first) continue;
    first = false;
    const std::string tag = between ? "between_" : "at_";
    for (int i = 0; i < 4; ++i) {
      signed_errors[tag + kIntrinsicNames[i] + "_px"] = e[i];
      sigmas[tag + kIntrinsicNames[i] + "_px"] = std::sqrt(vi.covariance(i, i));
    }
    for (int i = 0; i < 6; ++i) {
      signed_errors[tag + "pose_" + kPose[i]] = d[i];
      sigmas[tag + "pose_" + kPose[i]] = std::sqrt(C(i, i));
    }
  }
  values["intrinsics_nees_calibrated"] = nees_cal / std::max(1, n_cal);
  values["intrinsics_nees_between"] = nees_between / std::max(1, n_between);
  values["pose_nees_at"] = nees_pose_at / std::max(1, n_at);
  values["pose_nees_between"] = nees_pose_between / std::max(1, n_between);
  values["intrinsics_within_3_sigma"] = within / std::max(1, n_comp);
  values["sigma0"] = JsonNumber(r->sigma0);
  errors["between_cx_px"] = std::abs(signed_errors.value("between_cx_px", 0.0));
  errors["between_translation_mm"] = std::hypot(signed_errors.value("between_pose_tx_mm", 0.0),
                                                signed_errors.value("between_pose_ty_mm", 0.0),
                                                signed_errors.value("between_pose_tz_mm", 0.0));
  if (select > 0) {
    auto sel = analysis::SelectIntrinsicsModel(sf.problem,
                                               ba::SmoothBasis(),
                                               options,
                                               {analysis::IntrinsicsModel::kShared,
                                                analysis::IntrinsicsModel::kPerGroup,
                                                analysis::IntrinsicsModel::kSmooth});
    if (!sel.ok()) return sel.status();
    for (auto mm : {analysis::IntrinsicsModel::kShared,
                    analysis::IntrinsicsModel::kPerGroup,
                    analysis::IntrinsicsModel::kSmooth}) {
      values[std::string("recommended_") + analysis::IntrinsicsModelName(mm)] =
          sel->recommended == mm ? 1 : 0;
    }
    for (const auto& sc : sel->scores) {
      values[std::string("held_out_d2_") + analysis::IntrinsicsModelName(sc.model)] =
          JsonNumber(sc.held_out_d2_mean);
    }
  }
  return RunRecordJson(r->converged(), r->TerminationText(), errors, signed_errors, sigmas, values);
}

std::string BudgetKey(ba::Source s) {
  switch (s) {
    case ba::Source::kPlatePixels: return "plate_pixels";
    case ba::Source::kObjectPixels: return "object_pixels";
    case ba::Source::kCt: return "ct";
    case ba::Source::kPlateManufacturing: return "plate_manufacturing";
    case ba::Source::kIntrinsicsPrior: return "intrinsics_prior";
    case ba::Source::kCalibration: return "calibration";
  }
  return "?";
}

// A synthetic joint problem (synthetic/synthetic_joint.h): calibration and pose in one bundle
// adjustment with the config's held intrinsics; accuracy of intrinsics and object poses against the
// truth and the error budget.
StatusOr<nlohmann::json> RunJoint(PoseStudyState* state, const RunSpec& run) {
  static const std::set<std::string> kSweeps = {"num_plate_views", "plate_noise_px",
                                                "pixel_noise_px", "ct_noise_mm"};
  for (const auto& kv : run.sweep) {
    if (!kSweeps.count(kv.first)) {
      return Status::Error("sweep variable '" + kv.first +
                           "' is not understood by joint problems (known: ct_noise_mm, "
                           "num_plate_views, pixel_noise_px, plate_noise_px)");
    }
  }
  const StudyProblem& sp = *run.problem;
  const std::string where = "problem '" + sp.name + "': synthetic";
  JsonMap m(sp.synthetic, where);
  std::string kind;
  m.String("kind", &kind);
  ba::SyntheticJointSpec spec;
  double n_plate = spec.num_plate_views;
  m.Number("num_plate_views", &n_plate, &plausible::kViews);
  m.Numbers("object_angles_deg", &spec.object_angles_deg);
  m.Number("sigma_plate_px", &spec.sigma_plate_px, &plausible::kPixelSigmaPx);
  m.Number("sigma_object_px", &spec.sigma_object_px, &plausible::kPixelSigmaPx);
  m.Number("sigma_ct_mm", &spec.sigma_ct_mm, &plausible::kCtSigmaMm);
  m.Number("plate_distance_mm", &spec.plate_distance_mm, &plausible::kDistanceMm);
  m.Number("object_distance_mm", &spec.object_distance_mm, &plausible::kDistanceMm);
  CARMBA_RETURN_IF_ERROR(m.Finish());
  if (!sp.options.is_null()) {
    return Status::Error("problem '" + sp.name + "': key 'options' applies to problem files");
  }
  spec.num_plate_views = static_cast<int>(run.SweepValue("num_plate_views", n_plate));
  spec.sigma_plate_px = run.SweepValue("plate_noise_px", spec.sigma_plate_px);
  spec.sigma_object_px = run.SweepValue("pixel_noise_px", spec.sigma_object_px);
  spec.sigma_ct_mm = run.SweepValue("ct_noise_mm", spec.sigma_ct_mm);
  if (spec.num_plate_views < 3 || spec.object_angles_deg.size() < 2 ||
      !(spec.sigma_plate_px > 0 && spec.sigma_object_px > 0 && spec.sigma_ct_mm > 0)) {
    return Status::Error(where + ": expected >= 3 plate views, >= 2 object views and noise > 0");
  }
  const StudyConfig& sc = *run.config;
  auto config = state->configs.Get(sc.file, [&] { return LoadSolverConfig(sc.file); });
  if (!config->ok()) return config->status();
  ba::BaOptions options = config->value().ToBaOptions();
  options.num_threads = 1;
  ba::SyntheticJoint sj = ba::MakeSyntheticJoint(spec, ba::NoiseSwitches(), run.seed);
  for (const auto& n : config->value().fix) {
    for (int i = 0; i < kNumIntrinsics; ++i) {
      if (n == kIntrinsicNames[i]) sj.problem.groups[0].free[i] = false;
    }
  }
  auto r = ba::SolveBundleAdjustment(sj.problem, options);
  if (!r.ok()) return r.status();
  const auto budget = ba::ComputeErrorBudget(sj.problem, *r, sj.pairs);
  nlohmann::json errors, signed_errors, sigmas, values, budget_json = nlohmann::json::object();
  const std::array<double, kNumIntrinsics> x = r->GroupIntrinsics(0);
  static const char* const kIntr[4] = {"fx_px", "fy_px", "cx_px", "cy_px"};
  for (int i = 0; i < 4; ++i) {
    signed_errors[kIntr[i]] = x[i] - sj.true_intrinsics[i];
    const ba::BudgetRow* row =
        ba::FindBudgetRow(budget, {ba::QuantityKind::kIntrinsic, 0, -1, -1, i});
    if (row) sigmas[kIntr[i]] = row->sigma;
  }
  errors["focal_px"] = Rms({x[kFx] - sj.true_intrinsics[kFx], x[kFy] - sj.true_intrinsics[kFy]});
  errors["principal_point_px"] =
      Rms({x[kCx] - sj.true_intrinsics[kCx], x[kCy] - sj.true_intrinsics[kCy]});
  std::vector<double> rot, trans;
  bool first = true;
  const std::string first_view = sj.problem.views[sj.pairs.empty() ? 0 : sj.pairs[0].first].id;
  for (size_t v = 0; v < sj.problem.views.size(); ++v) {
    if (sj.problem.views[v].kind != ba::ViewKind::kObject) continue;
    const Pose6 pose = r->ViewPose(static_cast<int>(v));
    const Eigen::Matrix3d R_est = RotationOf(pose.head<3>());
    const Eigen::Matrix3d R_true = RotationOf(sj.true_poses[v].head<3>());
    const Eigen::Vector3d d = RvecFromRotation(R_est * R_true.transpose()) * kRadToDeg;
    const Eigen::Vector3d dt =
        Eigen::Vector3d(pose[3], pose[4], pose[5]) - sj.true_poses[v].tail<3>();
    rot.push_back(d.norm());
    trans.push_back(dt.norm());
    if (!first) continue;
    first = false;
    const char* const kRot[] = {"v0_rx_deg", "v0_ry_deg", "v0_rz_deg"};
    const char* const kTrans[] = {"v0_tx_mm", "v0_ty_mm", "v0_tz_mm"};
    std::array<double, ba::kNumSources> rot_var{}, trans_var{};
    for (int a = 0; a < 3; ++a) {
      signed_errors[kRot[a]] = d[a];
      signed_errors[kTrans[a]] = dt[a];
      const ba::BudgetRow* br =
          ba::FindBudgetRow(budget, ba::QuantityKey::ViewRotation(static_cast<int>(v), a));
      const ba::BudgetRow* bt =
          ba::FindBudgetRow(budget, ba::QuantityKey::ViewTranslation(static_cast<int>(v), a));
      sigmas[kRot[a]] = br->sigma;
      sigmas[kTrans[a]] = bt->sigma;
      for (int s = 0; s < ba::kNumSources; ++s) {
        rot_var[s] += br->source_sigma[s] * br->source_sigma[s] / 3;
        trans_var[s] += bt->source_sigma[s] * bt->source_sigma[s] / 3;
      }
    }
    for (int s = 0; s < ba::kNumSources; ++s) {
      if (rot_var[s] <= 0 && trans_var[s] <= 0) continue;
      budget_json["v0_rotation_deg." + BudgetKey(static_cast<ba::Source>(s))] =
          std::sqrt(rot_var[s]);
      budget_json["v0_translation_mm." + BudgetKey(static_cast<ba::Source>(s))] =
          std::sqrt(trans_var[s]);
    }
  }
  errors["rotation_deg"] = Rms(rot);
  errors["translation_mm"] = Rms(trans);
  std::vector<double> validation;
  for (const auto& [a, b] : sj.pairs) {
    const double est =
        RelativeRotationAngle(r->ViewPose(a).data(), r->ViewPose(b).data()) * kRadToDeg;
    const double truth =
        RelativeRotationAngle(sj.true_poses[a].data(), sj.true_poses[b].data()) * kRadToDeg;
    const std::string name =
        "pair_" + sj.problem.views[a].id + "_" + sj.problem.views[b].id + "_deg";
    signed_errors[name] = est - truth;
    sigmas[name] = ba::FindBudgetRow(budget, ba::QuantityKey::PairRelativeRotation(a, b))->sigma;
    validation.push_back(est - truth);
  }
  errors["validation_deg"] = Rms(validation);
  const ba::BudgetRow* fx =
      ba::FindBudgetRow(budget, {ba::QuantityKind::kIntrinsic, 0, -1, -1, kFx});
  if (fx) {
    for (int s = 0; s < ba::kNumSources; ++s) {
      if (fx->source_sigma[s] > 0)
        budget_json["fx_px." + BudgetKey(static_cast<ba::Source>(s))] = fx->source_sigma[s];
    }
  }
  values["rms_plate_px"] = JsonNumber(r->rms_plate_px);
  values["rms_object_px"] = JsonNumber(r->rms_object_px);
  values["iterations"] = r->iterations;
  values["sigma0"] = JsonNumber(r->sigma0);
  values["chi2_p_value"] = JsonNumber(r->chi2_p_value);
  values["first_view"] = first_view;
  nlohmann::json out;
  out["converged"] = r->converged();
  out["termination"] = r->TerminationText();
  out["errors"] = errors;
  out["signed_errors"] = signed_errors;
  out["sigmas"] = sigmas;
  out["values"] = values;
  out["budget"] = budget_json;
  return out;
}

// One calibration of seeded synthetic views; accuracy of the intrinsics against the truth.
StatusOr<nlohmann::json> RunCalibration(PoseStudyState* state, const RunSpec& run) {
  const StudyProblem& sp = *run.problem;
  const StudyConfig& sc = *run.config;
  for (const auto& kv : run.sweep) {
    if (kv.first != "pixel_noise_px" && kv.first != "num_views" && kv.first != "k1") {
      return Status::Error("sweep variable '" + kv.first + "' is not understood by calibration "
                           "studies (known: k1, num_views, pixel_noise_px)");
    }
  }
  if (!sc.options.is_null()) {
    return Status::Error("config '" + sc.name + "': key 'options' is not supported; put the "
                         "settings in " + sc.file);
  }
  auto entry = state->calibrations.Get(sp.base_dir + "|" + sp.name,
                                       [&] { return ParseCalibrationSynthetic(sp); });
  if (!entry->ok()) return entry->status();
  auto options = state->calib_configs.Get(sc.file, [&]() -> StatusOr<CalibrationOptions> {
    CalibrationOptions o;
    CARMBA_RETURN_IF_ERROR(LoadCalibrationOptions(sc.file, &o));
    return o;
  });
  if (!options->ok()) return options->status();
  CalibrationOptions opt = options->value();
  opt.solve.num_threads = 1;
  CalibrationEntry e = entry->value();
  const double nan = std::nan("");
  const double noise = run.SweepValue("pixel_noise_px", nan);
  const double views = run.SweepValue("num_views", nan);
  const double k1 = run.SweepValue("k1", nan);
  if (!std::isnan(noise)) e.views.noise_sigma_px = noise;
  if (!std::isnan(views)) {
    if (views != std::floor(views) || views < 1) {
      return Status::Error("sweep num_views: expected integers >= 1");
    }
    e.views.num_views = static_cast<int>(views);
  }
  if (!std::isnan(k1)) e.camera.params[4] = k1;
  e.views.seed = run.seed;
  const ObservationSet obs =
      MakeSyntheticViews(e.camera.params, e.camera.width, e.camera.height, e.grid, e.views);
  StatusOr<CalibrationResult> result = Calibrate(obs, opt);
  if (!result.ok()) return result.status();
  const auto& est = result->camera.params;
  const auto& truth = e.camera.params;
  nlohmann::json errors = nlohmann::json::object(), signed_errors = nlohmann::json::object(),
                 sigmas = nlohmann::json::object(), values = nlohmann::json::object();
  errors["focal_px"] = std::sqrt(0.5 * (std::pow(est[0] - truth[0], 2) +
                                        std::pow(est[1] - truth[1], 2)));
  errors["principal_point_px"] = std::hypot(est[2] - truth[2], est[3] - truth[3]);
  for (int i = 0; i < kNumIntrinsics; ++i) {
    if (!result->free.empty() && !result->free[i]) continue;  // held: no error to speak of
    const std::string name = std::string(kIntrinsicNames[i]) + (i < 4 ? "_px" : "");
    signed_errors[name] = est[i] - truth[i];
    if (std::isfinite(result->sigma[i]) && result->sigma[i] > 0) sigmas[name] = result->sigma[i];
  }
  values["rms_px"] = JsonNumber(result->rms_px);
  values["iterations"] = result->engine->iterations;
  values["sigma_px"] = JsonNumber(result->sigma_px);
  double worst = 0;
  for (const auto& ps : result->projection_sigma) worst = std::max(worst, ps.worst_px);
  values["projection_sigma_worst_px"] = JsonNumber(worst);
  return RunRecordJson(result->engine->converged(),
                       result->engine->TerminationText(),
                       errors,
                       signed_errors,
                       sigmas,
                       values);
}

// The predicted error budget of the first view from the engine (ba/quantities.h): the shares of
// the variance of its pose from pixel noise (the object views) and CT noise (the markers' priors),
// first order, Var(f) = sum_s G H^-1 J_s^T J_s H^-1 G^T. Reported as 1-sigma contributions (RMS
// over the three axes) to the first view's rotation (small rotations about the camera axes, deg)
// and translation (mm); their squares add up to the total. Empty without a covariance.
nlohmann::json PredictedBudget(const PoseSolution& sol, const SolverConfig& config) {
  nlohmann::json budget = nlohmann::json::object();
  if (!config.refine || sol.views.empty() || !sol.ba_result || !sol.ba_result->covariance) {
    return budget;
  }
  const auto rows = ba::ComputeErrorBudget(*sol.ba_problem, *sol.ba_result, {});
  for (const auto& [name, source] :
       {std::pair<std::string, ba::Source>{"pixel_noise", ba::Source::kObjectPixels},
        {"ct_noise", ba::Source::kCt}}) {
    double rot = 0, trans = 0;
    for (const auto& row : rows) {
      const double s = row.source_sigma[static_cast<int>(source)];
      if (row.quantity.key.view != 0) continue;
      if (row.quantity.key.kind == ba::QuantityKind::kViewRotation) rot += s * s;
      if (row.quantity.key.kind == ba::QuantityKind::kViewTranslation) trans += s * s;
    }
    budget["v0_rotation_deg." + name] = std::sqrt(rot / 3);
    budget["v0_translation_mm." + name] = std::sqrt(trans / 3);
  }
  return budget;
}

nlohmann::json MakeResult(const Problem& problem,
                          const PoseSolution& sol,
                          const SolverConfig& config) {
  nlohmann::json errors = nlohmann::json::object(), signed_errors = nlohmann::json::object(),
                 sigmas = nlohmann::json::object(), values = nlohmann::json::object();
  std::map<std::string, size_t> view_index;
  for (size_t v = 0; v < sol.views.size(); ++v) view_index[sol.views[v].id] = v;
  // Accuracy against the truth.
  std::vector<double> rot, trans, tre;
  for (size_t v = 0; v < sol.views.size(); ++v) {
    const ViewSolution& vs = sol.views[v];
    auto t = problem.truth.object_poses.find(vs.id);
    if (t == problem.truth.object_poses.end()) continue;
    const Eigen::Matrix3d R_est = RotationOf(vs.cam_from_object.head<3>());
    const Eigen::Matrix3d R_true = RotationOf(t->second.head<3>());
    const Eigen::Vector3d t_est = vs.cam_from_object.tail<3>(), t_true = t->second.tail<3>();
    rot.push_back(AngleBetweenRotations(R_est, R_true) * kRadToDeg);
    trans.push_back((t_est - t_true).norm());
    for (const auto& m : problem.fiducials) {
      const auto tm = problem.truth.markers.find(m.id);
      const Eigen::Vector3d x =
          tm != problem.truth.markers.end() ? tm->second : MarkerInProblemFrame(problem, m);
      tre.push_back(((R_est * x + t_est) - (R_true * x + t_true)).norm());
    }
    if (v == 0) {
      // Small rotation about the camera axes, R_est = exp(d) R_true (the solver's sigma of the
      // rotation is for this left perturbation), and the translation error.
      const Eigen::Vector3d d = RvecFromRotation(R_est * R_true.transpose()) * kRadToDeg;
      const Eigen::Vector3d dt = t_est - t_true;
      const char* const kRot[] = {"v0_rx_deg", "v0_ry_deg", "v0_rz_deg"};
      const char* const kTrans[] = {"v0_tx_mm", "v0_ty_mm", "v0_tz_mm"};
      for (int i = 0; i < 3; ++i) {
        signed_errors[kRot[i]] = d[i];
        signed_errors[kTrans[i]] = dt[i];
        if (sol.has_covariance) {
          sigmas[kRot[i]] = JsonNumber(vs.sigma_rotation_deg[i]);
          sigmas[kTrans[i]] = JsonNumber(vs.sigma_translation_mm[i]);
        }
      }
    }
  }
  if (!rot.empty()) {
    errors["rotation_deg"] = Rms(rot);
    errors["translation_mm"] = Rms(trans);
    errors["tre_mm"] = Rms(tre);
  }
  std::vector<double> validation;
  for (const auto& ps : sol.validation) {
    const auto ta = problem.truth.object_poses.find(ps.a),
               tb = problem.truth.object_poses.find(ps.b);
    if (ta != problem.truth.object_poses.end() && tb != problem.truth.object_poses.end()) {
      const double truth = RelativeRotationAngle(ta->second.data(), tb->second.data()) * kRadToDeg;
      const std::string name = "pair_" + ps.a + "_" + ps.b + "_deg";
      signed_errors[name] = ps.relative_rotation_deg - truth;
      if (sol.has_covariance) sigmas[name] = JsonNumber(ps.sigma_relative_rotation_deg);
      validation.push_back(ps.relative_rotation_deg - truth);
    } else if (ps.expected_deg) {
      validation.push_back(ps.relative_rotation_deg - *ps.expected_deg);
    }
  }
  if (!validation.empty()) errors["validation_deg"] = Rms(validation);
  const ba::BaResult& engine = *sol.ba_result;
  values["rms_px"] = JsonNumber(engine.rms_object_px);
  values["iterations"] = engine.iterations;
  values["sigma0"] = JsonNumber(engine.sigma0);
  values["chi2_p_value"] = JsonNumber(engine.chi2_p_value);
  // Reprojection residuals of the final state, px.
  nlohmann::json residuals = nlohmann::json::array();
  for (size_t v = 0; v < problem.object_views.size() && v < sol.views.size(); ++v) {
    for (const auto& o : problem.object_views[v].observations) {
      const auto m = sol.markers.find(o.marker_id);
      if (m == sol.markers.end()) continue;
      double uv[2];
      if (!ProjectPoint(problem.camera->params.data(),
                        sol.views[v].cam_from_object.data(),
                        m->second.data(),
                        uv)) {
        continue;
      }
      residuals.push_back(uv[0] - o.uv_px.x());
      residuals.push_back(uv[1] - o.uv_px.y());
    }
  }
  nlohmann::json r;
  r["converged"] = sol.converged;
  r["termination"] = sol.termination;
  r["errors"] = errors;
  r["signed_errors"] = signed_errors;
  r["sigmas"] = sigmas;
  r["values"] = values;
  r["residuals_px"] = residuals;
  r["budget"] = PredictedBudget(sol, config);
  return r;
}

StatusOr<nlohmann::json> RunPose(PoseStudyState* state, const RunSpec& run) {
  if (IsCalibration(*run.problem)) return RunCalibration(state, run);
  if (IsJoint(*run.problem)) return RunJoint(state, run);
  if (IsFlex(*run.problem)) return RunFlex(state, run);
  for (const auto& kv : run.sweep) {
    if (!KnownSweeps().count(kv.first)) {
      return Status::Error("sweep variable '" + kv.first +
                           "' is not understood by pose studies (known: ct_noise_mm, k1, "
                           "num_views, pixel_noise_px)");
    }
  }
  const StudyConfig& sc = *run.config;
  if (!sc.options.is_null()) {
    return Status::Error("config '" + sc.name + "': key 'options' is not supported by pose "
                         "studies; put the settings in " + sc.file);
  }
  auto config = state->configs.Get(sc.file, [&] { return LoadSolverConfig(sc.file); });
  if (!config->ok()) return config->status();
  SolverConfig cfg = config->value();
  cfg.num_threads = 1;  // one run per core

  const StudyProblem& sp = *run.problem;
  const double nan = std::nan("");
  const double pixel_noise = run.SweepValue("pixel_noise_px", nan);
  const double ct_noise = run.SweepValue("ct_noise_mm", nan);
  const double num_views = run.SweepValue("num_views", nan);
  const double k1 = run.SweepValue("k1", nan);
  if (!std::isnan(num_views) && num_views != std::floor(num_views)) {
    return Status::Error("sweep num_views: expected integers");
  }
  Problem problem;
  if (!sp.synthetic.is_null()) {
    if (!sp.options.is_null()) {
      return Status::Error("problem '" + sp.name + "': key 'options' applies to problem files");
    }
    auto entry = state->synthetic.Get(sp.base_dir + "|" + sp.name,
                                      [&] { return ParseSynthetic(sp); });
    if (!entry->ok()) return entry->status();
    SyntheticPoseSpec spec = entry->value().spec;
    const double sigma_px = std::isnan(pixel_noise) ? entry->value().sigma_px : pixel_noise;
    const double sigma_ct = std::isnan(ct_noise) ? entry->value().sigma_ct_mm : ct_noise;
    if (!(sigma_px > 0) || !(sigma_ct > 0)) {
      return Status::Error("problem '" + sp.name + "': pixel and CT noise must be > 0 (they "
                           "whiten the residuals), got " + std::to_string(sigma_px) + " px, " +
                           std::to_string(sigma_ct) + " mm");
    }
    if (!std::isnan(k1)) spec.camera.params[4] = k1;
    if (!std::isnan(num_views)) {
      const int n = static_cast<int>(num_views);
      if (n < 1 || n > static_cast<int>(spec.view_angles_deg.size())) {
        return Status::Error("sweep num_views = " + std::to_string(n) + ": expected 1.." +
                             std::to_string(spec.view_angles_deg.size()));
      }
      spec.view_angles_deg.resize(static_cast<size_t>(n));
      std::vector<std::pair<int, int>> pairs;
      for (const auto& pr : spec.pairs) {
        if (pr.first < n && pr.second < n) pairs.push_back(pr);
      }
      spec.pairs = pairs;
    }
    problem = MakeSyntheticPoseProblem(spec, sigma_px, sigma_ct, run.seed);
    problem.name = sp.name;
  } else {
    StatusOr<MonteCarlo> mc = ParseProblemOptions(sp);
    if (!mc.ok()) return mc.status();
    if (!std::isnan(k1)) return Status::Error("sweep k1 applies to synthetic problems only");
    auto measured = state->problems.Get(sp.file, [&] { return LoadProblem(sp.file); });
    if (!measured->ok()) return measured->status();
    if (*mc == MonteCarlo::kNone) {
      if (!std::isnan(pixel_noise) || !std::isnan(ct_noise)) {
        return Status::Error("problem '" + sp.name + "': sweeping pixel_noise_px or ct_noise_mm "
                             "needs options: {monte_carlo: resimulate} for a problem file");
      }
      problem = measured->value();
    } else {
      auto truth = state->truths.Get(sp.file, [&] { return MakeResimulationTruth(**measured); });
      if (!truth->ok()) return truth->status().WithContext(sp.file);
      problem = truth->value();
      const double sigma_px = std::isnan(pixel_noise) ? problem.object_sigma_px : pixel_noise;
      if (!(sigma_px > 0)) return Status::Error("pixel_noise_px: expected > 0");
      Rng rng(run.seed);
      for (auto& m : problem.fiducials) {
        double sigma_ct = ct_noise;
        if (std::isnan(sigma_ct)) sigma_ct = std::sqrt(m.covariance.trace() / 3);
        if (!(sigma_ct > 0)) return Status::Error("ct_noise_mm: expected > 0");
        m.p_in_object += sigma_ct * RandomVector<3>(Gaussian, rng);
        m.covariance = Eigen::Matrix3d::Identity() * sigma_ct * sigma_ct;
      }
      for (auto& v : problem.object_views) {
        for (auto& o : v.observations) {
          o.uv_px += sigma_px * RandomVector<2>(Gaussian, rng);
        }
      }
      problem.object_sigma_px = sigma_px;
    }
    if (!std::isnan(num_views)) CARMBA_RETURN_IF_ERROR(KeepViews(static_cast<int>(num_views),
                                                                 &problem));
  }
  StatusOr<PoseSolution> sol = SolvePoseProblem(problem, cfg);
  if (!sol.ok()) return sol.status();
  return MakeResult(problem, *sol, cfg);
}

}  // namespace

RunFunction PoseStudyRunFunction() {
  auto state = std::make_shared<PoseStudyState>();
  return [state](const RunSpec& run) { return RunPose(state.get(), run); };
}

}  // namespace carmba
