// `carmba triangulate`: points seen in two or more object views (an instrument tip, an unmatched
// blob) -> their 3-D positions in the CT (object) frame with 3x3 covariances
// (analysis/triangulation.h). The problem is solved again with its config (the same solve as
// `carmba solve`, deterministic), so the joint covariance of the views' poses and the intrinsics is
// at hand.
//
//   carmba triangulate --problem P --config C --points points.csv --out DIR
//   carmba triangulate --problem P --config C --pixels 'VIEW=U,V;VIEW=U,V' --out DIR
//
// points.csv: columns view, u_px, v_px; optional `point` (a name; rows of one point together
// form it, default "1") and optional pixel covariance cov_uu, cov_uv, cov_vv (px^2) or sigma_px;
// without them --sigma_px, else the view's sigma_px from the problem.
// Writes DIR/triangulation.json (per point: position, covariance, its parts, ray angle,
// residuals, variance by source, warnings) and DIR/points.csv (id, x_mm, y_mm, z_mm, cov_xx ..
// cov_zz: the format of `carmba ct-fiducials`). Every error is one line; nothing is written then.
// Nearly parallel rays are a warning (stderr and the JSON), parallel ones an error.
#include <gflags/gflags.h>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>

#include "analysis/triangulation.h"
#include "cli/command.h"
#include "cli/common_flags.h"
#include "io/pixel_csv.h"
#include "joint/joint_solver.h"
#include "problem/pose_solver.h"
#include "util/csv.h"  // ParseFiniteDouble
#include "util/file_util.h"
#include "util/format.h"
#include "util/plausible.h"

DEFINE_string(points, "",
              "CSV of the points' pixels: view,u_px,v_px[,point][,cov_uu,cov_uv,cov_vv | "
              ",sigma_px].");
DEFINE_string(pixels, "", "One point's pixels instead of --points: 'VIEW=U,V;VIEW=U,V'.");
DEFINE_double(sigma_px, 0,
              "Pixel sigma of the points (0: the CSV's columns, else the view's sigma_px).");
DEFINE_double(min_angle_deg, 5.0, "Warn when the widest pair of rays is closer than this (deg).");

namespace {

using namespace carmba;

// One point's pixels as the pixel-CSV reader hands them on (io/pixel_csv.h; `where` is
// "file:line" or "--pixels"; a zero covariance: none given).
struct PointInput {
  std::string name;
  std::vector<PixelCsvRow> pixels;
};

StatusOr<std::vector<PointInput>> ReadPointsCsv(const std::string& path) {
  PixelCsvColumns columns;
  columns.key = "point";
  columns.key_required = false;
  columns.absent_key = "1";
  columns.integer_key = false;
  columns.sigma_column = true;
  auto rows = ReadPixelCsv(path, columns);
  if (!rows.ok()) return rows.status();
  if (rows->empty()) return Status::Error(path + ": no rows");
  std::vector<PointInput> points;
  std::map<std::string, size_t> index;
  for (const PixelCsvRow& row : *rows) {
    auto it = index.find(row.key);
    if (it == index.end()) {
      it = index.emplace(row.key, points.size()).first;
      points.push_back({row.key, {}});
    }
    points[it->second].pixels.push_back(row);
  }
  return points;
}

StatusOr<std::vector<PointInput>> ParsePixelsFlag(const std::string& s) {
  PointInput p;
  p.name = "1";
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ';')) {
    const size_t eq = item.find('='), comma = item.find(',', eq == std::string::npos ? 0 : eq);
    double u = 0, v = 0;
    if (eq == std::string::npos || comma == std::string::npos ||
        !ParseFiniteDouble(item.substr(eq + 1, comma - eq - 1), &u) ||
        !ParseFiniteDouble(item.substr(comma + 1), &v)) {
      return Status::Error("--pixels: '" + item + "': expected VIEW=U,V with finite numbers (px)");
    }
    std::string err;
    if (!CheckRange("--pixels u", u, plausible::kPixelCoordinatePx, &err) ||
        !CheckRange("--pixels v", v, plausible::kPixelCoordinatePx, &err)) {
      return Status::Error(err);
    }
    PixelCsvRow px;
    px.view = item.substr(0, eq);
    px.key = p.name;
    px.uv_px = Eigen::Vector2d(u, v);
    px.where = "--pixels";
    p.pixels.push_back(px);
  }
  if (p.pixels.empty()) return Status::Error("--pixels: no VIEW=U,V given");
  return std::vector<PointInput>{p};
}

struct Solved {
  std::shared_ptr<const ba::BaProblem> problem;
  std::shared_ptr<const ba::BaResult> result;
  bool mirrored = false;   // pose problem with handedness mirrored: the solve's y is -y of the CT
  std::string kind;
};

StatusOr<Solved> Solve() {
  Solved s;
  auto config = LoadSolverConfig(FLAGS_config);
  if (!config.ok()) return config.status();
  auto problem = LoadProblem(FLAGS_problem);
  if (!problem.ok()) return problem.status();
  if (!problem->IsPoseProblem()) {
    auto sol = SolveJointProblem(*problem, *config);
    if (!sol.ok()) return sol.status();
    s.problem = std::make_shared<const ba::BaProblem>(std::move(sol->ba_problem));
    s.result = std::make_shared<const ba::BaResult>(std::move(sol->result));
    s.kind = "joint";
    return s;
  }
  auto sol = SolvePoseProblem(*problem, *config);
  if (!sol.ok()) return sol.status();
  if (!config->refine || config->covariance_algorithm != ba::CovarianceAlgorithm::kSchur) {
    return Status::Error(FLAGS_config + ": triangulation needs the refined solve's covariance "
                         "(refine: true, covariance: {algorithm: schur})");
  }
  s.problem = sol->ba_problem;
  s.result = sol->ba_result;
  s.mirrored = problem->handedness == Handedness::kMirrored;
  s.kind = "pose";
  return s;
}

// The flags' usage errors ("" when there are none); fills the triangulation options.
std::string UsageError(analysis::TriangulationOptions* topt) {
  if (FLAGS_problem.empty()) return "--problem is required";
  if (FLAGS_config.empty()) return "--config is required";
  if (FLAGS_out.empty()) return "--out is required";
  if (FLAGS_points.empty() == FLAGS_pixels.empty()) {
    return "give either --points CSV or --pixels 'VIEW=U,V;VIEW=U,V'";
  }
  std::string err;
  if (FLAGS_sigma_px != 0 &&
      !CheckRange("--sigma_px", FLAGS_sigma_px, plausible::kPixelSigmaPx, &err)) {
    return err;
  }
  topt->min_ray_angle_deg = FLAGS_min_angle_deg;
  if (!topt->Check(&err)) return "--min-angle-deg: " + err;
  return "";
}

// The solve's object views by id, and their ids listed for an error message.
struct ObjectViews {
  std::map<std::string, int> index;
  std::string ids;
};
ObjectViews ObjectViewsOf(const ba::BaProblem& bp) {
  ObjectViews o;
  for (size_t v = 0; v < bp.views.size(); ++v) {
    if (bp.views[v].kind != ba::ViewKind::kObject) continue;
    o.index[bp.views[v].id] = static_cast<int>(v);
    o.ids += (o.ids.empty() ? "" : ", ") + bp.views[v].id;
  }
  return o;
}

// A point's pixels as observations of the solve's views, with their covariances (--sigma-px, the
// point's own, or the view's sigma).
StatusOr<std::vector<analysis::PixelObservation>> PointObservations(const PointInput& p,
                                                                    const ObjectViews& views,
                                                                    const ba::BaProblem& bp) {
  std::vector<analysis::PixelObservation> obs;
  for (const auto& px : p.pixels) {
    auto it = views.index.find(px.view);
    if (it == views.index.end()) {
      return Status::Error(px.where + ": view '" + px.view +
                           "' is not an object view of the problem (object views: " + views.ids +
                           ")");
    }
    analysis::PixelObservation o;
    o.view = it->second;
    o.uv_px = px.uv_px;
    const double s = FLAGS_sigma_px > 0 ? FLAGS_sigma_px : bp.views[o.view].sigma_px;
    o.covariance_px2 = px.HasCovariance() && FLAGS_sigma_px == 0
                           ? px.covariance_px2
                           : Eigen::Matrix2d::Identity() * s * s;
    obs.push_back(o);
  }
  return obs;
}

// One point of triangulation.json, in the CT frame: X and C are the point and its covariance
// there (F: the solve's object frame -> CT).
nlohmann::json PointJson(const PointInput& p,
                         const analysis::TriangulatedPoint& t,
                         const std::vector<analysis::PixelObservation>& obs,
                         const ba::BaProblem& bp,
                         const Eigen::Matrix3d& F,
                         const Eigen::Vector3d& X,
                         const Eigen::Matrix3d& C) {
  nlohmann::json views = nlohmann::json::array();
  for (size_t i = 0; i < obs.size(); ++i) {
    views.push_back(
        {{"view", bp.views[obs[i].view].id},
         {"u_px", obs[i].uv_px[0]},
         {"v_px", obs[i].uv_px[1]},
         {"residual_px", {JsonNumber(t.residual_px[i][0]), JsonNumber(t.residual_px[i][1])}},
         {"rejected", t.rejected[i] != 0}});
  }
  nlohmann::json by_source;
  for (int s = 0; s < ba::kNumSources; ++s) {
    by_source[ba::SourceName(static_cast<ba::Source>(s))] = JsonNumber(t.solve_trace_by_source[s]);
  }
  by_source["the point's pixels"] = JsonNumber(t.covariance_pixels.trace());
  return {{"id", p.name},
          {"p_in_ct_mm", {X[0], X[1], X[2]}},
          {"covariance_mm2", JsonRows(C)},
          {"sigma_mm",
           {JsonNumber(std::sqrt(C(0, 0))),
            JsonNumber(std::sqrt(C(1, 1))),
            JsonNumber(std::sqrt(C(2, 2)))}},
          {"rms_3d_mm", JsonNumber(std::sqrt(C.trace()))},
          {"covariance_pixels_mm2", JsonRows(F * t.covariance_pixels * F)},
          {"covariance_solve_mm2", JsonRows(F * t.covariance_solve * F)},
          {"covariance_calibration_mm2", JsonRows(F * t.covariance_calibration * F)},
          {"variance_by_source_mm2", by_source},
          {"max_ray_angle_deg", JsonNumber(t.max_ray_angle_deg)},
          {"rms_px", JsonNumber(t.rms_px)},
          {"views", views},
          {"chi2", JsonNumber(t.chi2)},
          {"dof", t.dof},
          {"chi2_p_value", JsonNumber(t.chi2_p_value)},
          {"warnings", t.warnings}};
}

// points.csv's header: the command, what the covariance holds, the columns.
std::string CsvHeader(ba::CalibrationUncertainty calibration) {
  std::ostringstream csv;
  csv << "# carmba triangulate --problem " << FLAGS_problem << " --config " << FLAGS_config
      << "\n# positions in the CT frame (mm), covariance mm^2 (the solve's "
      << (calibration == ba::CalibrationUncertainty::kEstimated ? "poses and intrinsics"
          : calibration == ba::CalibrationUncertainty::kConsidered
              ? "poses, with the held intrinsics' calibration covariance"
              : "poses (intrinsics held, calibration uncertainty left out)")
      << " and the points' pixels)\n"
      << "id,x_mm,y_mm,z_mm,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz\n";
  return csv.str();
}

// One row of points.csv.
std::string CsvRow(const std::string& name, const Eigen::Vector3d& X, const Eigen::Matrix3d& C) {
  char line[512];
  std::snprintf(line,
                sizeof line,
                "%s,%.6f,%.6f,%.6f,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n",
                name.c_str(),
                X[0],
                X[1],
                X[2],
                C(0, 0),
                C(0, 1),
                C(0, 2),
                C(1, 1),
                C(1, 2),
                C(2, 2));
  return line;
}

// triangulation.json's statement of what the covariances hold.
std::string CovarianceStatement(ba::CalibrationUncertainty calibration, const ba::BaResult& br) {
  const std::string scale = br.covariance_scale == 1.0 ? "a-priori" : "a-posteriori";
  return calibration == ba::CalibrationUncertainty::kEstimated
             ? "the solve's joint covariance of poses and intrinsics (" + scale +
                   " sigmas) and the points' pixel noise"
         : calibration == ba::CalibrationUncertainty::kConsidered
             ? "the solve's covariance of the poses (" + scale +
                   " sigmas), the held intrinsics' calibration covariance from camera.json "
                   "(considered: covariance_calibration_mm2) and the points' pixel noise"
             : std::string(
                   "the solve's covariance of the poses and the points' pixel noise; the "
                   "intrinsics are held and camera.json has no covariance (or the config "
                   "says consider_calibration: false): the calibration's uncertainty is NOT "
                   "included");
}

// triangulation.json and points.csv into --out, all or nothing.
Status WriteOutputs(const nlohmann::json& j, const std::string& csv) {
  StagedOutputDir staged(FLAGS_out);
  Status s = staged.Begin();
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "triangulation.json"), j.dump(2) + "\n");
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "points.csv"), csv);
  if (s.ok()) s = staged.Commit(/*replace_all=*/false);
  return s;
}

int RunTriangulate() {
  const char* cmd = "triangulate";
  analysis::TriangulationOptions topt;
  const std::string usage = UsageError(&topt);
  if (!usage.empty()) return cli::FailUsage(cmd, usage);
  {
    const Status s = cli::CheckOutDir();
    if (!s.ok()) return cli::Fail(cmd, s);
  }
  auto points = FLAGS_points.empty() ? ParsePixelsFlag(FLAGS_pixels) : ReadPointsCsv(FLAGS_points);
  if (!points.ok()) return cli::Fail(cmd, points.status());
  cli::Step(cmd, "solving the views' problem");
  auto solved = Solve();
  if (!solved.ok()) return cli::Fail(cmd, solved.status());
  cli::Step(cmd, "triangulating " + std::to_string(points->size()) + " points");
  const ba::BaProblem& bp = *solved->problem;
  const ba::BaResult& br = *solved->result;
  const ObjectViews object_views = ObjectViewsOf(bp);
  const ba::CalibrationUncertainty calibration = ba::CalibrationUncertaintyOf(bp);
  // The solve's object frame -> the CT frame (a mirrored pose problem negates y).
  const Eigen::Matrix3d F = Eigen::Vector3d(1, solved->mirrored ? -1 : 1, 1).asDiagonal();

  nlohmann::json jpoints = nlohmann::json::array();
  std::string csv = CsvHeader(calibration);
  std::vector<std::string> warnings;
  for (const PointInput& p : *points) {
    auto obs = PointObservations(p, object_views, bp);
    if (!obs.ok()) return cli::Fail(cmd, obs.status());
    auto t = analysis::TriangulatePoint(bp, br, *obs, topt);
    if (!t.ok()) {
      const std::string src = FLAGS_points.empty() ? "--pixels" : FLAGS_points;
      return cli::Fail(cmd, src + ": point '" + p.name + "': " + t.status().message());
    }
    const Eigen::Vector3d X = F * t->p_in_object;
    const Eigen::Matrix3d C = F * t->covariance * F;
    for (const auto& w : t->warnings) warnings.push_back("point '" + p.name + "': " + w);
    jpoints.push_back(PointJson(p, *t, *obs, bp, F, X, C));
    csv += CsvRow(p.name, X, C);
    std::printf(
        "point %s: (%.3f, %.3f, %.3f) mm, sigma (%.3f, %.3f, %.3f) mm, rays %.1f deg "
        "apart, %zu views\n",
        p.name.c_str(),
        X[0],
        X[1],
        X[2],
        std::sqrt(C(0, 0)),
        std::sqrt(C(1, 1)),
        std::sqrt(C(2, 2)),
        t->max_ray_angle_deg,
        obs->size());
  }
  nlohmann::json j;
  j["problem"] = {{"file", FLAGS_problem}, {"kind", solved->kind}, {"config", FLAGS_config}};
  j["frame"] = "CT (object) frame, mm";
  j["covariance"] = CovarianceStatement(calibration, br);
  j["points"] = jpoints;
  j["warnings"] = warnings;
  cli::Step(cmd, "writing the outputs");
  const Status s = WriteOutputs(j, csv);
  if (!s.ok()) return cli::Fail(cmd, s);
  for (const auto& w : warnings) std::cerr << "carmba triangulate: warning: " << w << std::endl;
  if (calibration == ba::CalibrationUncertainty::kLeftOut) {
    std::cerr << "carmba triangulate: note: the intrinsics are held without a calibration "
                 "covariance: the calibration's uncertainty is not in the covariance" << std::endl;
  }
  std::cout << "wrote " << FLAGS_out << "/triangulation.json and " << FLAGS_out << "/points.csv"
            << std::endl;
  return 0;
}

}  // namespace

CARMBA_COMMAND_FLAGS(triangulate, "problem,config,out,force");
CARMBA_REGISTER_COMMAND(triangulate,
                        "Triangulate points seen in two or more object views (CT frame, 3x3 "
                        "covariance from the solve and the pixels).",
                        RunTriangulate);
