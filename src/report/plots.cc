#include "report/plots.h"

#include <stdlib.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include <ceres/jet.h>
#include <Eigen/Eigenvalues>

#include "ba/view_intrinsics.h"
#include "camera/camera_model.h"
#include "geometry/rotation.h"
#include "util/format.h"
#include "util/file_util.h"
#include "util/python_worker.h"
#include "util/temp_paths.h"

namespace carmba {
namespace {

std::string LastLine(const std::string& text) {
  std::istringstream in(text);
  std::string line, last;
  while (std::getline(in, line)) {
    if (!line.empty()) last = line;
  }
  return last;
}

}  // namespace

// What the plot script imports (scripts/report_plots.py's first lines), done while the caller
// works.
constexpr const char* kPlotPreload =
    "import numpy\nimport matplotlib\nmatplotlib.use('Agg')\nimport matplotlib.pyplot\n";

PlotProcess::PlotProcess(const PlotOptions& options) : options_(options) {
  if (!options_.enabled) {
    set_.disabled = true;
    set_.unavailable = "not drawn (--no-plots)";
    done_ = true;
    return;
  }
  namespace fs = std::filesystem;
  std::error_code ec;
  dir_ = (fs::temp_directory_path(ec) / "carmba_plots_XXXXXX").string();
  {
    const SignalCriticalSection making;  // a SIGTERM now must find the directory registered
    if (ec || ::mkdtemp(dir_.data()) == nullptr) {
      dir_.clear();
      set_.unavailable = "cannot make a temporary directory for the plot script";
      done_ = true;
      return;
    }
    dir_slot_ = RegisterTempPath(dir_);  // removed on SIGINT / SIGTERM (util/temp_paths.h)
  }
  worker_ = std::make_unique<PythonWorker>(options_.python, kPlotPreload);
}

PlotProcess::~PlotProcess() {
  worker_.reset();  // kills an interpreter that was not waited for
  if (!dir_.empty()) {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  UnregisterTempPath(dir_slot_);
}

void PlotProcess::Draw(const nlohmann::json& data) {
  if (done_ || drawn_) return;
  drawn_ = true;
  const std::string script = JoinPath(dir_, "report_plots.py"), in = JoinPath(dir_, "in.json"),
                    out = JoinPath(dir_, "out.json"), err = JoinPath(dir_, "stderr.txt");
  Status s = WriteFileAtomic(script, ReportPlotsScript());
  if (s.ok()) s = WriteFileAtomic(in, data.dump());
  if (!s.ok()) {
    set_.unavailable = "cannot write the plot script's input: " + s.message();
    done_ = true;
    return;
  }
  worker_->Start(script, {in, out}, "/dev/null", err);
}

PlotSet PlotProcess::Result() {
  if (done_) return set_;
  done_ = true;
  if (!drawn_) {
    set_.unavailable = "no plot data";
    return set_;
  }
  const int code = worker_->Wait(options_.timeout_s);
  set_.seconds = worker_->seconds();
  StatusOr<std::string> err_text = ReadFile(JoinPath(dir_, "stderr.txt"));
  const std::string last = err_text.ok() ? LastLine(*err_text) : "";
  if (code == 3) {
    set_.unavailable = last.empty() ? "matplotlib is not available" : last;
  } else if (code == PythonWorker::kCannotRun || code == 126) {
    set_.unavailable = options_.python + " cannot be run (exit " + std::to_string(code) + ")";
  } else if (code == PythonWorker::kTimedOut) {
    set_.unavailable = "the plot script took longer than " + std::to_string(options_.timeout_s) +
                       " s and was stopped";
  } else if (code != 0) {
    set_.unavailable = "the plot script failed (exit " + std::to_string(code) + ")" +
                       (last.empty() ? "" : ": " + last);
  } else {
    StatusOr<std::string> text = ReadFile(JoinPath(dir_, "out.json"));
    try {
      const nlohmann::json j = nlohmann::json::parse(text.ok() ? *text : "");
      for (const auto& p : j.at("plots")) {
        set_.plots.push_back({p.at("id").get<std::string>(), p.at("title").get<std::string>(),
                              p.at("caption").get<std::string>(),
                              p.at("png_base64").get<std::string>()});
      }
      for (const auto& n : j.at("notes")) set_.notes.push_back(n.get<std::string>());
      for (const auto& e : j.at("errors")) set_.errors.push_back(e.get<std::string>());
    } catch (const std::exception& e) {
      set_.plots.clear();
      set_.unavailable = std::string("the plot script's output cannot be read: ") + e.what();
    }
  }
  return set_;
}

PlotSet MakePlots(const nlohmann::json& data, const PlotOptions& options) {
  PlotProcess p(options);
  p.Draw(data);
  return p.Result();
}

ReportFiles RenderReport(const ReportDoc& doc,
                         const std::string& title,
                         const nlohmann::json& plot_data,
                         const PlotOptions& options) {
  return RenderReport(doc, title, MakePlots(plot_data, options));
}

ReportFiles RenderReport(const ReportDoc& doc, const std::string& title, const PlotSet& plots) {
  ReportFiles f;
  f.markdown = doc.Markdown();
  std::string note;
  if (plots.disabled) {
    note = "Plots " + plots.unavailable + ". The tables below are complete.";
  } else if (!plots.unavailable.empty()) {
    note = "Plots unavailable: " + plots.unavailable + ". The tables below are complete; "
           "install python3-matplotlib (scripts/setup.sh) for the plots.";
    f.warning = "report.html has no plots: " + plots.unavailable;
  } else if (!plots.errors.empty()) {
    f.warning = "report.html is missing " + std::to_string(plots.errors.size()) +
                " plot(s) the plot script failed to draw: " + plots.errors.front();
  }
  ReportDoc html_doc = doc;
  if (!plots.notes.empty() || !plots.errors.empty()) {
    html_doc.Heading(2, "Plot notes");
    std::vector<std::string> items = plots.notes;
    for (const auto& e : plots.errors) items.push_back("Plot failed (please report): " + e);
    html_doc.List(items);
  }
  f.html = html_doc.Html(title, plots.plots, note);
  return f;
}

nlohmann::json IntrinsicsProjectionUncertainty(const std::string& name,
                                               const double* intrinsics,
                                               const Eigen::MatrixXd& cov,
                                               int width,
                                               int height,
                                               double distance_mm,
                                               int nx,
                                               int ny) {
  using Jet = ceres::Jet<double, kNumIntrinsics>;
  nlohmann::json u = nlohmann::json::array(), v = nlohmann::json::array(),
                 worst = nlohmann::json::array();
  Jet intr[kNumIntrinsics];
  for (int i = 0; i < kNumIntrinsics; ++i) intr[i] = Jet(intrinsics[i], i);
  for (int r = 0; r < ny; ++r) {
    for (int c = 0; c < nx; ++c) {
      const double uv[2] = {(width - 1) * c / double(nx - 1), (height - 1) * r / double(ny - 1)};
      u.push_back(uv[0]);
      v.push_back(uv[1]);
      double xy[2];
      if (!UnprojectToNormalized(intrinsics, uv, xy)) {
        worst.push_back(nullptr);
        continue;
      }
      const Jet p[3] = {Jet(distance_mm * xy[0]), Jet(distance_mm * xy[1]), Jet(distance_mm)};
      Jet q[2];
      if (!ProjectCamPoint(intr, p, q)) {
        worst.push_back(nullptr);
        continue;
      }
      Eigen::Matrix<double, 2, kNumIntrinsics> J;
      J.row(0) = q[0].v.transpose();
      J.row(1) = q[1].v.transpose();
      const Eigen::Matrix2d C = J * cov * J.transpose();
      const double top = Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(C).eigenvalues()(1);
      worst.push_back(JsonNumber(std::sqrt(std::max(0.0, top))));
    }
  }
  return {{"name", name},
          {"distance_mm", distance_mm},
          {"definition",
           "1-sigma uncertainty (worst direction, px) of where a point at " +
               Fixed(distance_mm, 0) +
               " mm along each pixel's ray, fixed in the camera frame, projects with the "
               "estimated intrinsics and their covariance (intrinsics only: the calibration's "
               "own uncertainty)."},
          {"nx", nx},
          {"ny", ny},
          {"u", u},
          {"v", v},
          {"worst_px", worst}};
}

nlohmann::json BaPlotData(const ba::BaProblem& problem,
                          const ba::BaResult& result,
                          const std::vector<ba::BudgetRow>* budget) {
  const ba::StateLayout& L = *result.layout;
  nlohmann::json d;
  for (const auto& g : problem.groups) {
    if (g.width > 0 && g.height > 0) {
      d["image_size"] = {g.width, g.height};
      break;
    }
  }
  std::map<int, int> marker_index;
  for (size_t m = 0; m < problem.markers.size(); ++m) marker_index[problem.markers[m].id] = m;
  nlohmann::json views = nlohmann::json::array();
  nlohmann::json plate_sources = nlohmann::json::array(), object_sources = nlohmann::json::array();
  double object_distance = 0, plate_distance = 0;
  int num_object = 0, num_plate = 0;
  for (size_t v = 0; v < problem.views.size(); ++v) {
    const ba::BaView& bv = problem.views[v];
    const bool plate = bv.kind == ba::ViewKind::kPlate;
    const Pose6 view_pose = result.ViewPose(static_cast<int>(v));
    const double* pose = view_pose.data();
    const std::array<double, kNumIntrinsics> view_intr =
        ba::IntrinsicsValueOfView(problem, result, static_cast<int>(v));  // smooth: at its angles
    const double* intr = view_intr.data();
    nlohmann::json u = nlohmann::json::array(), vv = nlohmann::json::array(),
                   du = nlohmann::json::array(), dv = nlohmann::json::array();
    for (size_t k = 0; k < bv.point_ids.size(); ++k) {
      if (v < result.dropped.size() && k < result.dropped[v].size() && result.dropped[v][k]) {
        continue;
      }
      const int id = bv.point_ids[k];
      Eigen::Vector3d p;
      if (plate) {
        p = result.PlatePoint(id);
      } else {
        auto it = marker_index.find(id);
        if (it == marker_index.end()) continue;
        p = result.MarkerPosition(it->second);
      }
      double uv[2];
      if (!ProjectPoint(intr, pose, p.data(), uv)) continue;
      u.push_back(bv.uv_px[k].x());
      vv.push_back(bv.uv_px[k].y());
      du.push_back(uv[0] - bv.uv_px[k].x());
      dv.push_back(uv[1] - bv.uv_px[k].y());
    }
    views.push_back({{"id", bv.id},
                     {"kind", plate ? "plate" : "object"},
                     {"rms_px", JsonNumber(result.views[v].rms_px)},
                     {"u", u},
                     {"v", vv},
                     {"du", du},
                     {"dv", dv}});
    const Eigen::Map<const Eigen::Vector3d> rvec(pose), t(pose + 3);
    const Eigen::Vector3d source = -RotationOf(rvec).transpose() * t;
    (plate ? plate_sources : object_sources)
        .push_back({{"id", bv.id}, {"p", {source.x(), source.y(), source.z()}}});
    (plate ? plate_distance : object_distance) += t.norm();
    ++(plate ? num_plate : num_object);
  }
  d["residual_views"] = views;
  nlohmann::json scenes = nlohmann::json::array();
  if (num_plate > 0) {
    nlohmann::json pts = nlohmann::json::array();
    for (size_t p = 0; p < problem.plate.points.size(); ++p) {
      const Eigen::Vector3d x = result.PlatePoint(static_cast<int>(p));
      pts.push_back({x[0], x[1], x[2]});
    }
    scenes.push_back({{"name", "plate"},
                      {"frame", "plate"},
                      {"pose_name", "cam_from_plate"},
                      {"points_label", "plate points"},
                      {"points", pts},
                      {"sources", plate_sources}});
  }
  nlohmann::json marker_items = nlohmann::json::array();
  if (num_object > 0) {
    nlohmann::json pts = nlohmann::json::array();
    for (size_t m = 0; m < problem.markers.size(); ++m) {
      const int mi = static_cast<int>(m);
      const Eigen::Vector3d x = result.MarkerPosition(mi);
      pts.push_back({x[0], x[1], x[2]});
      if (result.covariance && !L.block(L.marker_block(mi)).constant) {
        marker_items.push_back({{"id", problem.markers[m].id},
                                {"p", {x[0], x[1], x[2]}},
                                {"cov", JsonRows(result.MarkerCovariance(mi))}});
      }
    }
    scenes.push_back({{"name", "object"},
                      {"frame", "object"},
                      {"pose_name", "cam_from_object"},
                      {"points_label", "markers"},
                      {"points", pts},
                      {"sources", object_sources}});
  }
  d["scenes"] = scenes;
  if (!marker_items.empty()) {
    d["markers"] = {{"frame", "object"},
                    {"items", marker_items},
                    {"note", "Estimated by the bundle adjustment from the CT centres (priors) and "
                             "the object views."}};
  }
  nlohmann::json cameras = nlohmann::json::array(), pu = nlohmann::json::array();
  const double distance = num_object > 0 ? object_distance / num_object
                                         : (num_plate > 0 ? plate_distance / num_plate : 0);
  for (size_t g = 0; g < problem.groups.size(); ++g) {
    const auto& grp = problem.groups[g];
    const std::string name = problem.groups.size() == 1 ? "the camera" : grp.name;
    // A smooth group's block holds coefficients, not one camera (its intrinsics against the
    // angle are the joint report's own plot).
    if (grp.smooth) continue;
    const int gi = static_cast<int>(g);
    const std::array<double, kNumIntrinsics> x = result.GroupIntrinsics(gi);
    cameras.push_back({{"name", name}, {"intrinsics", std::vector<double>(x.begin(), x.end())}});
    if (result.covariance && !L.block(L.group_block(gi)).constant && grp.width > 0 &&
        grp.height > 0 && distance > 0) {
      pu.push_back(IntrinsicsProjectionUncertainty(
          name, x.data(), result.GroupIntrinsicsCovariance(gi), grp.width, grp.height, distance));
    }
  }
  d["cameras"] = cameras;
  if (!pu.empty()) d["projection_uncertainty"] = pu;
  if (budget && !budget->empty()) {
    nlohmann::json sources = nlohmann::json::array(), rows = nlohmann::json::array();
    const std::vector<ba::Source> active = ba::ActiveSources(*budget);
    for (ba::Source k : active) sources.push_back(ba::SourceName(k));
    for (const auto& r : *budget) {
      nlohmann::json shares = nlohmann::json::array();
      for (ba::Source k : active) shares.push_back(JsonNumber(r.share[static_cast<int>(k)]));
      rows.push_back({{"quantity", r.quantity.name},
                      {"unit", r.quantity.unit},
                      {"value", JsonNumber(r.quantity.value)},
                      {"sigma", JsonNumber(r.sigma)},
                      {"shares", shares}});
    }
    d["budget"] = {{"sources", sources}, {"rows", rows}};
  }
  return d;
}

}  // namespace carmba
