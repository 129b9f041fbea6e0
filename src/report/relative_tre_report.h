// result.json blocks and report sections (report.md and report.html) for the relative C-arm poses
// (analysis/relative_pose.h) and the leave-one-marker-out TRE (analysis/tre.h), shared by the pose
// and the joint front ends.
#pragma once

#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "analysis/relative_pose.h"
#include "analysis/tre.h"
#include "report/report_doc.h"

namespace carmba {

// "relative_poses": per pair a, b, cam_b_from_cam_a {rvec, t_mm}, covariance_6x6, the rotation
// angle and its sigma, sigmas about view b's axes, baseline; with `truth` (cam_from_object by
// view id; may be empty) the errors: rotation error (deg), its 3-dof Mahalanobis distance, NEES.
nlohmann::json RelativePosesJson(const ba::BaProblem& problem,
                                 const std::vector<analysis::RelativePoseEstimate>& poses,
                                 const std::map<std::string, Pose6>& truth);
void AppendRelativePoses(ReportDoc* doc,
                         const ba::BaProblem& problem,
                         const std::vector<analysis::RelativePoseEstimate>& poses,
                         const std::map<std::string, Pose6>& truth);

// "tre": FLE, RMS measured / predicted / Fitzpatrick, and per marker.
nlohmann::json TreJson(const analysis::TreResult& tre);
void AppendTre(ReportDoc* doc, const analysis::TreResult& tre);

}  // namespace carmba
