// The one translation of a Problem into the engine's problem (ba_assembly.h).
#include "problem/ba_assembly.h"

#include <map>
#include <opencv2/calib3d.hpp>
#include <set>

#include "geometry/rotation.h"
#include "pose/posit.h"

namespace carmba {

ba::BaView ToBaObjectView(const PoseView& pose_view, double sigma_px) {
  ba::BaView view;
  view.id = pose_view.id;
  view.kind = ba::ViewKind::kObject;
  view.sigma_px = sigma_px;
  bool per_observation = false, full = false;
  for (const auto& o : pose_view.observations) {
    per_observation |= o.sigma_px > 0;
    full |= o.HasCovariance();
  }
  for (const auto& o : pose_view.observations) {
    view.point_ids.push_back(o.marker_id);
    view.uv_px.push_back(o.uv_px);
    const double sigma = o.sigma_px > 0 ? o.sigma_px : sigma_px;
    if (per_observation) view.obs_sigma_px.push_back(sigma);
    if (full) {
      view.obs_covariance_px2.push_back(
          o.HasCovariance() ? o.covariance_px2
                            : Eigen::Matrix2d(sigma * sigma * Eigen::Matrix2d::Identity()));
    }
  }
  return view;
}

StatusOr<Pose6> InitialObjectPose(const Camera& cam,
                                  Initializer initializer,
                                  const std::vector<Eigen::Vector3d>& pts,
                                  const std::vector<Eigen::Vector2d>& uv) {
  switch (initializer) {
    case Initializer::kPosit:
      return PositPose(cam, pts, uv, PositOptions());
    case Initializer::kLegacyPosit: {
      // OpenCV 1.x cvPOSIT as the thesis used it, but in this problem's camera convention:
      // undistorted pixels relative to the principal point, one focal length (fx + fy) / 2,
      // float32, non-orthonormal rows; the result is projected to the nearest rotation.
      std::vector<Eigen::Vector2d> img(uv.size());
      for (size_t i = 0; i < uv.size(); ++i) {
        double xy[2];
        if (!UnprojectToNormalized(cam.params.data(), uv[i].data(), xy)) {
          return Status::Error("legacy POSIT: pixel " + std::to_string(i) +
                               " cannot be undistorted");
        }
        img[i] = Eigen::Vector2d(xy[0] * cam.params[kFx], xy[1] * cam.params[kFy]);
      }
      PositOptions o;
      o.mode = PositMode::kLegacy;
      auto r = Posit(pts, img, 0.5 * (cam.params[kFx] + cam.params[kFy]), o);
      if (!r.ok()) return r.status();
      const Eigen::Matrix3d R = NearestRotation(r->R);
      Pose6 pose;
      pose.head<3>() = RvecFromRotation(R);
      pose.tail<3>() = r->t - R * pts[0];
      return pose;
    }
    case Initializer::kEpnp:
    case Initializer::kSqpnp: {
      cv::Mat obj(static_cast<int>(pts.size()), 3, CV_64F),
          img(static_cast<int>(uv.size()), 2, CV_64F);
      for (size_t i = 0; i < pts.size(); ++i) {
        for (int c = 0; c < 3; ++c) obj.at<double>(static_cast<int>(i), c) = pts[i][c];
        for (int c = 0; c < 2; ++c) img.at<double>(static_cast<int>(i), c) = uv[i][c];
      }
      const cv::Matx33d K(
          cam.params[kFx], 0, cam.params[kCx], 0, cam.params[kFy], cam.params[kCy], 0, 0, 1);
      const cv::Matx<double, 1, 5> dist(
          cam.params[kK1], cam.params[kK2], cam.params[kP1], cam.params[kP2], cam.params[kK3]);
      cv::Mat rvec, tvec;
      bool ok = false;
      try {
        ok = cv::solvePnP(
            obj,
            img,
            K,
            dist,
            rvec,
            tvec,
            false,
            initializer == Initializer::kEpnp ? cv::SOLVEPNP_EPNP : cv::SOLVEPNP_SQPNP);
      } catch (const cv::Exception& e) {
        return Status::Error(std::string(NameOf(kInitializerNames, initializer)) + ": " + e.what());
      }
      if (!ok || rvec.empty()) {
        return Status::Error(std::string(NameOf(kInitializerNames, initializer)) + " failed");
      }
      Pose6 pose;
      for (int c = 0; c < 3; ++c) pose[c] = rvec.at<double>(c), pose[3 + c] = tvec.at<double>(c);
      if (!pose.allFinite() || !(pose[5] > 0)) {
        return Status::Error(std::string(NameOf(kInitializerNames, initializer)) +
                             " returned an invalid pose");
      }
      return pose;
    }
  }
  return Status::Error("unknown initializer");
}

namespace {

// The fiducials some object view observes, in the problem's handedness, in file order.
void AddMarkers(const Problem& problem, ba::BaProblem* bp) {
  std::set<int> observed;
  for (const auto& v : problem.object_views) {
    for (const auto& o : v.observations) observed.insert(o.marker_id);
  }
  for (const auto& m : problem.fiducials) {
    if (!observed.count(m.id)) continue;
    bp->markers.push_back(
        {m.id, MarkerInProblemFrame(problem, m), MarkerCovarianceInProblemFrame(problem, m)});
  }
}

// The object views, each initialised by the config's initializer with its group's initial
// intrinsics.
Status AddObjectViews(const Problem& problem,
                      const SolverConfig& config,
                      const std::vector<int>& groups,
                      const ProgressFn& progress,
                      ba::BaProblem* bp) {
  std::map<int, Eigen::Vector3d> marker;
  for (const auto& m : bp->markers) marker[m.id] = m.p_ct;
  for (size_t k = 0; k < problem.object_views.size(); ++k) {
    ba::BaView view = ToBaObjectView(problem.object_views[k], problem.object_sigma_px);
    view.group = groups.empty() ? 0 : groups[k];
    Camera cam;
    std::copy(bp->groups[view.group].initial.begin(),
              bp->groups[view.group].initial.end(),
              cam.params.begin());
    std::vector<Eigen::Vector3d> pts;
    for (int id : view.point_ids) pts.push_back(marker.at(id));
    auto init = InitialObjectPose(cam, config.initializer, pts, view.uv_px);
    if (!init.ok()) {
      return Status::Error(problem.path + ": object view '" + view.id +
                           "': " + init.status().message());
    }
    view.initial = *init;
    bp->views.push_back(std::move(view));
    if (progress) progress(problem.object_views[k].id);
  }
  return Status::Ok();
}

// The C-arm angles of the views that have them.
void AddAngles(const Problem& problem, ba::BaProblem* bp) {
  for (auto& v : bp->views) {
    auto it = problem.angles.find(v.id);
    if (it == problem.angles.end()) continue;
    v.has_angles = true;
    v.primary_deg = it->second.first;
    v.secondary_deg = it->second.second;
  }
}

// Problem::validation as indices into the engine problem's views.
std::vector<std::pair<int, int>> ValidationPairs(const Problem& problem, const ba::BaProblem& bp) {
  std::map<std::string, int> object_index;
  for (size_t v = 0; v < bp.views.size(); ++v) {
    if (bp.views[v].kind == ba::ViewKind::kObject)
      object_index[bp.views[v].id] = static_cast<int>(v);
  }
  std::vector<std::pair<int, int>> pairs;
  for (const auto& vp : problem.validation) {
    pairs.emplace_back(object_index.at(vp.a), object_index.at(vp.b));
  }
  return pairs;
}

}  // namespace

StatusOr<AssembledProblem> ToBaProblem(const Problem& problem,
                                       const SolverConfig& config,
                                       BaAssemblyInput input,
                                       const ProgressFn& progress) {
  AssembledProblem out;
  ba::BaProblem& bp = out.problem;
  bp = ToBaPlateProblem(
      problem.name, problem.plate, std::move(input.groups), std::move(input.plate_views));
  bp.plate.free = problem.plate_free;
  bp.plate.sigma_mm = problem.plate_sigma_mm;
  bp.marker_radius_mm = problem.marker_diameter_mm / 2;
  AddMarkers(problem, &bp);
  CARMBA_RETURN_IF_ERROR(AddObjectViews(problem, config, input.object_view_groups, progress, &bp));
  AddAngles(problem, &bp);
  out.validation_pairs = ValidationPairs(problem, bp);
  return out;
}

}  // namespace carmba
