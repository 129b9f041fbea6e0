#include "report/relative_tre_report.h"

#include <cmath>
#include <sstream>

#include "report/result_json.h"
#include "util/format.h"

namespace carmba {
namespace {

const Pose6* Find(const std::map<std::string, Pose6>& truth, const std::string& id) {
  auto it = truth.find(id);
  return it == truth.end() ? nullptr : &it->second;
}

}  // namespace

nlohmann::json RelativePosesJson(const ba::BaProblem& problem,
                                 const std::vector<analysis::RelativePoseEstimate>& poses,
                                 const std::map<std::string, Pose6>& truth) {
  nlohmann::json a = nlohmann::json::array();
  for (const auto& e : poses) {
    const std::string& ia = problem.views[e.view_a].id;
    const std::string& ib = problem.views[e.view_b].id;
    nlohmann::json j = {{"a", ia},
                        {"b", ib},
                        {"cam_b_from_cam_a", PoseToJson(e.cam_b_from_cam_a)},
                        {"covariance_6x6", JsonRows(e.covariance)},
                        {"covariance_order", "rx ry rz (rad, rotation vector), tx ty tz (mm)"},
                        {"angle_deg", JsonNumber(e.angle_deg)},
                        {"sigma_angle_deg", JsonNumber(e.sigma_angle_deg)},
                        {"sigma_rotation_deg", JsonVector(e.sigma_rotation_deg)},
                        {"sigma_translation_mm", JsonVector(e.sigma_translation_mm)},
                        {"baseline_mm", JsonNumber(e.baseline_mm)},
                        {"covariance_calibration_6x6", JsonRows(e.covariance_calibration)},
                        {"sigma_angle_calibration_deg", JsonNumber(e.sigma_angle_calibration_deg)}};
    const Pose6* ta = Find(truth, ia);
    const Pose6* tb = Find(truth, ib);
    if (ta && tb) {
      const analysis::RelativePoseError err = analysis::CompareRelativePose(e, *ta, *tb);
      Pose6 t;
      analysis::RelativePose(ta->data(), tb->data(), t.data());
      j["truth"] = PoseToJson(t);
      j["rotation_error_deg"] = JsonNumber(err.rotation_error_deg);
      j["rotation_error_sigma"] = JsonNumber(err.rotation_mahalanobis);
      j["angle_error_sigma"] = JsonNumber(err.angle_error_sigma);
      j["nees"] = JsonNumber(err.nees);
    }
    a.push_back(j);
  }
  return a;
}

void AppendRelativePoses(ReportDoc* d,
                         const ba::BaProblem& problem,
                         const std::vector<analysis::RelativePoseEstimate>& poses,
                         const std::map<std::string, Pose6>& truth) {
  d->Heading(2, "Relative C-arm poses");
  if (poses.empty()) {
    d->Paragraph("Not computed (needs the engine's covariance).");
    return;
  }
  d->Paragraph(
      "cam_b_from_cam_a = cam_b_from_object * inverse(cam_a_from_object), with its 6x6 "
      "covariance from the joint covariance of the two poses (result.json `relative_poses`). "
      "Rotation sigmas are small rotations about view b's camera axes; the baseline is the "
      "distance between the two sources.");
  bool any_truth = false;
  for (const auto& e : poses) {
    any_truth |= Find(truth, problem.views[e.view_a].id) && Find(truth, problem.views[e.view_b].id);
  }
  std::vector<std::string> header = {"a", "b", "angle (deg)", "sigma", "sigma rot x / y / z (deg)",
                                     "t (mm)", "sigma t x / y / z (mm)", "baseline (mm)"};
  if (any_truth) {
    for (const char* h :
         {"rotation error (deg)", "rotation error (sigma, 3 dof)", "NEES (6 dof)"}) {
      header.push_back(h);
    }
  }
  std::vector<std::vector<std::string>> rows;
  for (const auto& e : poses) {
    const std::string& ia = problem.views[e.view_a].id;
    const std::string& ib = problem.views[e.view_b].id;
    const Eigen::Vector3d t = e.cam_b_from_cam_a.tail<3>();
    std::vector<std::string> row = {
        ia,
        ib,
        Fmt("%.3f", e.angle_deg),
        Fmt("%.3f", e.sigma_angle_deg),
        Fmt("%.3f", e.sigma_rotation_deg[0]) + " / " + Fmt("%.3f", e.sigma_rotation_deg[1]) +
            " / " + Fmt("%.3f", e.sigma_rotation_deg[2]),
        Fmt("%.1f", t[0]) + ", " + Fmt("%.1f", t[1]) + ", " + Fmt("%.1f", t[2]),
        Fmt("%.2f", e.sigma_translation_mm[0]) + " / " + Fmt("%.2f", e.sigma_translation_mm[1]) +
            " / " + Fmt("%.2f", e.sigma_translation_mm[2]),
        Fmt("%.1f", e.baseline_mm)};
    if (any_truth) {
      const Pose6* ta = Find(truth, ia);
      const Pose6* tb = Find(truth, ib);
      if (ta && tb) {
        const analysis::RelativePoseError err = analysis::CompareRelativePose(e, *ta, *tb);
        row.push_back(Fmt("%.4f", err.rotation_error_deg));
        row.push_back(Fmt("%.2f", err.rotation_mahalanobis));
        row.push_back(Fmt("%.2f", err.nees));
      } else {
        row.insert(row.end(), {"", "", ""});
      }
    }
    rows.push_back(std::move(row));
  }
  d->Table(header, rows);
}

nlohmann::json TreJson(const analysis::TreResult& t) {
  nlohmann::json markers = nlohmann::json::array();
  for (const auto& m : t.markers) {
    nlohmann::json j = {{"id", m.marker_id}, {"p_ct_mm", JsonVector(m.p_ct)}};
    if (!m.skipped.empty()) {
      j["skipped"] = m.skipped;
    } else {
      j["p_triangulated_mm"] = JsonVector(m.p_triangulated);
      j["covariance_mm2"] = JsonRows(m.covariance);
      j["num_views"] = m.num_views;
      j["views_left_out"] = m.num_views_left_out;
      j["max_ray_angle_deg"] = JsonNumber(m.max_ray_angle_deg);
      j["error_mm"] = JsonNumber(m.error_mm);
      j["predicted_rms_mm"] = JsonNumber(m.predicted_rms_mm);
      j["predicted_tre_mm"] = JsonNumber(m.predicted_tre_mm);
      j["fitzpatrick_tre_mm"] = JsonNumber(m.fitzpatrick_tre_mm);
      j["fitzpatrick_rms_mm"] = JsonNumber(m.fitzpatrick_rms_mm);
      j["mahalanobis2"] = JsonNumber(m.mahalanobis2);
    }
    markers.push_back(j);
  }
  return {{"what",
           "leave-one-marker-out: marker k dropped from the solve, triangulated from its pixels, "
           "compared with its CT position (analysis/tre.h)"},
          {"evaluated", t.num_evaluated},
          {"rms_error_mm", JsonNumber(t.rms_error_mm)},
          {"rms_predicted_mm", JsonNumber(t.rms_predicted_mm)},
          {"rms_fitzpatrick_mm", JsonNumber(t.rms_fitzpatrick_mm)},
          {"mean_mahalanobis2_per_dof", JsonNumber(t.mean_mahalanobis2_per_dof)},
          {"fle_mm", JsonNumber(t.fle_mm)},
          {"fle_ct_mm", JsonNumber(t.fle_ct_mm)},
          {"fle_xray_mm", JsonNumber(t.fle_xray_mm)},
          {"time_s", JsonNumber(t.time_s)},
          {"markers", markers}};
}

void AppendTre(ReportDoc* d, const analysis::TreResult& t) {
  d->Heading(2, "Target registration error (leave one marker out)");
  d->Paragraph(
      "Each marker in turn is dropped from the solve (its CT prior and its pixels), triangulated "
      "from its pixels with the other markers' solve, and compared with its CT position. "
      "`predicted` is what the covariance says for that difference, sqrt(tr(C_triangulated + "
      "C_CT)); `TRE` the part against the true position, sqrt(tr(C_triangulated)). "
      "Fitzpatrick's formula (3-D point registration, TRE^2 = FLE^2 / N (1 + 1/3 sum d^2 / f^2)) "
      "is shown beside it for the same layout with FLE^2 = FLE_CT^2 + FLE_X-ray^2 (" +
      Fmt("%.3f", t.fle_ct_mm) + " and " + Fmt("%.3f", t.fle_xray_mm) +
      " mm RMS 3-D), plus the target's own localisation to compare with the measured error. "
      "The FRE is not an accuracy estimate and is not shown.");
  if (t.num_evaluated > 0) {
    d->Paragraph("RMS over " + std::to_string(t.num_evaluated) + " markers: measured " +
                 Fmt("%.3f", t.rms_error_mm) + " mm, predicted by the covariance " +
                 Fmt("%.3f", t.rms_predicted_mm) + " mm, by Fitzpatrick's formula " +
                 Fmt("%.3f", t.rms_fitzpatrick_mm) + " mm; mean e^T C^-1 e / 3 = " +
                 Fmt("%.2f", t.mean_mahalanobis2_per_dof) + " (" + Fmt("%.0f", 1e3 * t.time_s) +
                 " ms).");
  }
  std::vector<std::vector<std::string>> rows;
  for (const auto& m : t.markers) {
    if (!m.skipped.empty()) {
      rows.push_back(
          {std::to_string(m.marker_id), "skipped: " + m.skipped, "", "", "", "", "", ""});
      continue;
    }
    rows.push_back({std::to_string(m.marker_id), std::to_string(m.num_views),
                    Fmt("%.3f", m.error_mm), Fmt("%.3f", m.predicted_rms_mm),
                    Fmt("%.3f", m.predicted_tre_mm), Fmt("%.3f", m.fitzpatrick_tre_mm),
                    Fmt("%.3f", m.fitzpatrick_rms_mm), Fmt("%.2f", m.mahalanobis2)});
  }
  d->Table({"marker", "views", "error (mm)", "predicted (mm)", "TRE (mm)", "Fitzpatrick TRE (mm)",
            "Fitzpatrick + target (mm)", "e^T C^-1 e"},
           rows);
}

}  // namespace carmba
