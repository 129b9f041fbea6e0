// carmba.solve -> carmba.Result, carmba.triangulate, carmba.tre, carmba.export_geometry: the
// functions `carmba solve`, `carmba triangulate` and `carmba export-geometry` call
// (src/cli/cmd_solve.cc, cmd_triangulate.cc, cmd_export_geometry.cc), so the numbers are the
// command's.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <optional>

#include "analysis/triangulation.h"
#include "ba/quantities.h"
#include "calib/crosscheck.h"
#include "export/geometry_export.h"
#include "export/view_geometry.h"
#include "joint/joint_solver.h"
#include "problem/pose_solver.h"
#include "python/bindings.h"
#include "report/joint_report.h"
#include "report/pose_report.h"
#include "report/relative_tre_report.h"
#include "util/file_util.h"

namespace carmba::python {
namespace {

// One solved problem (pose or joint) as the Python Result holds it.
struct Solved {
  std::string kind;  // "pose" | "joint"
  SolverConfig config;
  std::shared_ptr<const Problem> input;        // the problem as read (problem/problem.h)
  std::shared_ptr<const PoseSolution> pose;    // kind pose
  std::shared_ptr<const JointSolution> joint;  // kind joint
  std::shared_ptr<const ba::BaProblem> bp;  // the engine's problem and result (both kinds)
  std::shared_ptr<const ba::BaResult> br;
  nlohmann::json json;  // result.json
  bool mirrored = false;  // pose problem with handedness mirrored (solve frame = CT with -y)

  const ba::BaProblem& problem() const {
    if (!bp) throw Error("this solve has no bundle adjustment (refine: false)");
    return *bp;
  }
  const ba::BaResult& result() const {
    problem();
    return *br;
  }
  const ba::BaResult& result_with_covariance() const {
    if (!result().covariance) {
      throw Error(config.path + ": no engine covariance (refine: true and covariance: "
                                "{algorithm: schur} compute it)");
    }
    return *br;
  }
};

struct View {
  std::string id, kind, group;
  Pose6 pose = Pose6::Zero();
  std::optional<Matrix6> covariance;
  Eigen::Vector3d sigma_rotation_deg = Eigen::Vector3d::Constant(NAN);
  Eigen::Vector3d sigma_translation_mm = Eigen::Vector3d::Constant(NAN);
  double rms_px = 0;
  int num_observations = 0;
};

struct Intrinsics {
  std::string group;
  std::vector<std::string> names;
  Eigen::VectorXd values;
  Eigen::MatrixXd covariance;  // over names; empty when unknown
  std::string uncertainty;     // "estimated" | "considered (held, camera.json's covariance)" ...
  int width = 0, height = 0;
};

// ---- block names: "intrinsics" (one group) / "intrinsics <group>", "view <id>" (object
// views), "plate <id>" (plate views), "marker <id>", "plate point <id>".
std::map<std::string, int> BlockNames(const ba::BaProblem& bp, const ba::StateLayout& L) {
  std::map<std::string, int> names;
  for (size_t g = 0; g < bp.groups.size(); ++g) {
    const int b = L.group_block(static_cast<int>(g));
    if (!bp.groups[g].name.empty()) names["intrinsics " + bp.groups[g].name] = b;
    if (bp.groups.size() == 1) names["intrinsics"] = b;
  }
  for (size_t v = 0; v < bp.views.size(); ++v) {
    const bool plate = bp.views[v].kind == ba::ViewKind::kPlate;
    names[(plate ? "plate " : "view ") + bp.views[v].id] = L.view_block(static_cast<int>(v));
  }
  for (size_t m = 0; m < bp.markers.size(); ++m) {
    names["marker " + std::to_string(bp.markers[m].id)] = L.marker_block(static_cast<int>(m));
  }
  for (size_t b = 0; b < L.blocks().size(); ++b) {
    const ba::BlockInfo& blk = L.block(static_cast<int>(b));
    if (blk.kind == ba::BlockKind::kPlatePoint) {
      names["plate point " + std::to_string(blk.index)] = static_cast<int>(b);
    }
  }
  return names;
}

int FindBlock(const Solved& s, const std::string& name) {
  const auto names = BlockNames(s.problem(), *s.result().layout);
  auto it = names.find(name);
  if (it != names.end()) return it->second;
  std::string known;
  int shown = 0;
  for (const auto& [n, b] : names) {
    if (shown++ < 12) known += (known.empty() ? "" : ", ") + ("'" + n + "'");
  }
  throw Error("block '" + name + "': no such parameter block (blocks: " + known +
              (names.size() > 12 ? ", ..." : "") + ")");
}

std::vector<std::string> BlockParameters(const Solved& s, int b) {
  const ba::StateLayout& L = *s.result().layout;
  const ba::BlockInfo& blk = L.block(b);
  std::vector<std::string> out;
  for (int i = 0; i < blk.size; ++i) {
    std::string n = L.ParameterName(b, i);
    if (!blk.label.empty() && n.rfind(blk.label + " ", 0) == 0) n = n.substr(blk.label.size() + 1);
    out.push_back(n);
  }
  return out;
}

// Cov(block a, block b) in the blocks' ambient parameters (BaResult::Covariance: the residuals'
// part scaled by the covariance scale plus a considered calibration's part).
Eigen::MatrixXd CrossCovariance(const Solved& s, const std::string& a, const std::string& b) {
  const ba::BaResult& r = s.result_with_covariance();
  return r.Cross(FindBlock(s, a), FindBlock(s, b));
}

// ---- views
std::vector<View> PoseViews(const Solved& s) {
  std::vector<View> out;
  for (const auto& v : s.pose->views) {
    View w;
    w.id = v.id;
    w.kind = "object";
    w.pose = v.cam_from_object;
    if (s.pose->has_covariance) w.covariance = v.covariance;
    w.sigma_rotation_deg = v.sigma_rotation_deg;
    w.sigma_translation_mm = v.sigma_translation_mm;
    w.rms_px = v.rms_px;
    w.num_observations = v.num_observations;
    out.push_back(w);
  }
  return out;
}

std::vector<View> JointViews(const Solved& s) {
  const ba::BaProblem& bp = *s.bp;
  const ba::BaResult& r = *s.br;
  std::vector<View> out;
  for (size_t v = 0; v < bp.views.size(); ++v) {
    const ba::BaView& bv = bp.views[v];
    View w;
    w.id = bv.id;
    w.kind = bv.kind == ba::ViewKind::kPlate ? "plate" : "object";
    w.group = bp.groups[bv.group].name;
    w.pose = r.ViewPose(static_cast<int>(v));
    if (r.covariance) w.covariance = r.ViewPoseCovariance(static_cast<int>(v));
    for (int a = 0; a < 3; ++a) {
      const auto* rot =
          ba::FindBudgetRow(s.joint->budget, ba::QuantityKey::ViewRotation(static_cast<int>(v), a));
      const auto* t = ba::FindBudgetRow(s.joint->budget,
                                        ba::QuantityKey::ViewTranslation(static_cast<int>(v), a));
      if (rot) w.sigma_rotation_deg[a] = rot->sigma;
      if (t) w.sigma_translation_mm[a] = t->sigma;
    }
    w.rms_px = r.views[v].rms_px;
    w.num_observations = r.views[v].num_observations;
    out.push_back(w);
  }
  return out;
}

// ---- intrinsics
std::vector<Intrinsics> PoseIntrinsics(const Solved& s) {
  const Camera& c = *s.input->camera;
  Intrinsics in;
  in.group = "shared";
  in.names.assign(kIntrinsicNames, kIntrinsicNames + kNumIntrinsics);
  in.values = Eigen::Map<const Eigen::VectorXd>(c.params.data(), kNumIntrinsics);
  in.width = c.width;
  in.height = c.height;
  if (!c.covariance.empty()) {
    // camera.json's covariance over its names, placed in the 9 x 9 (names not in it: 0).
    in.covariance = Eigen::MatrixXd::Zero(kNumIntrinsics, kNumIntrinsics);
    std::vector<int> idx;
    for (const auto& n : c.covariance_names) {
      idx.push_back(static_cast<int>(
          std::find(in.names.begin(), in.names.end(), n) - in.names.begin()));
    }
    for (size_t i = 0; i < idx.size(); ++i) {
      for (size_t j = 0; j < idx.size(); ++j) in.covariance(idx[i], idx[j]) = c.covariance[i][j];
    }
  }
  in.uncertainty = ba::CalibrationUncertaintyNote(ba::CalibrationUncertaintyOf(s.problem()));
  return {in};
}

std::vector<Intrinsics> JointIntrinsics(const Solved& s) {
  const ba::BaProblem& bp = *s.bp;
  const ba::BaResult& r = *s.br;
  std::vector<Intrinsics> out;
  for (size_t g = 0; g < bp.groups.size(); ++g) {
    const int b = r.layout->group_block(static_cast<int>(g));
    Intrinsics in;
    in.group = bp.groups[g].name;
    in.names = BlockParameters(s, b);
    in.values = Eigen::Map<const Eigen::VectorXd>(r.block(b), r.layout->block(b).size);
    if (r.covariance) in.covariance = r.Covariance({b});
    in.uncertainty = ba::CalibrationUncertaintyNote(ba::CalibrationUncertaintyOf(bp));
    in.width = bp.groups[g].width;
    in.height = bp.groups[g].height;
    out.push_back(in);
  }
  return out;
}

// ---- budget, relative poses, statistics
std::vector<std::pair<int, int>> PosePairs(const Solved& s) {
  std::map<std::string, int> index;
  for (size_t v = 0; v < s.bp->views.size(); ++v) index[s.bp->views[v].id] = static_cast<int>(v);
  std::vector<std::pair<int, int>> pairs;
  for (const auto& p : s.input->validation) pairs.emplace_back(index.at(p.a), index.at(p.b));
  return pairs;
}

py::list BudgetList(const std::vector<ba::BudgetRow>& budget) {
  py::list out;
  for (const auto& row : budget) {
    py::dict sources, shares;
    for (int k = 0; k < ba::kNumSources; ++k) {
      const char* n = ba::SourceName(static_cast<ba::Source>(k));
      sources[n] = row.source_sigma[k];
      shares[n] = row.share[k];
    }
    py::dict d;
    d["quantity"] = row.quantity.name;
    d["unit"] = row.quantity.unit;
    d["value"] = row.quantity.value;
    d["sigma"] = row.sigma;
    d["sigma_by_source"] = sources;
    d["share_by_source"] = shares;
    out.append(d);
  }
  return out;
}

py::list ErrorBudget(const Solved& s) {
  if (s.kind == "joint") return BudgetList(s.joint->budget);
  s.result_with_covariance();
  return BudgetList(ba::ComputeErrorBudget(*s.bp, *s.br, PosePairs(s)));
}

py::list RelativePoses(const Solved& s) {
  const auto& rel = s.kind == "joint" ? s.joint->relative_poses : s.pose->relative_poses;
  py::list out;
  for (const auto& e : rel) {
    py::dict d;
    d["a"] = s.bp->views[e.view_a].id;
    d["b"] = s.bp->views[e.view_b].id;
    d["cam_b_from_cam_a"] = ToNumpyVector(e.cam_b_from_cam_a);
    d["covariance_6x6"] = ToNumpy(e.covariance);
    d["covariance_calibration_6x6"] = ToNumpy(e.covariance_calibration);
    d["angle_deg"] = e.angle_deg;
    d["sigma_angle_deg"] = e.sigma_angle_deg;
    d["sigma_rotation_deg"] = ToNumpyVector(e.sigma_rotation_deg);
    d["sigma_translation_mm"] = ToNumpyVector(e.sigma_translation_mm);
    d["baseline_mm"] = e.baseline_mm;
    out.append(d);
  }
  return out;
}

// result.json's statistics (report/engine_json.h, as the command writes them) with the solver's
// iterations and termination.
py::dict Statistics(const Solved& s) {
  py::dict d = ToPython(s.json.value("statistics", nlohmann::json::object()));
  const nlohmann::json solver = s.json.value("solver", nlohmann::json::object());
  d["iterations"] = ToPython(solver.value("iterations", nlohmann::json()));
  d["termination"] = ToPython(solver.value("termination", nlohmann::json()));
  return d;
}

// ---- solve
std::shared_ptr<Solved> SolvePose(std::shared_ptr<const Problem> problem,
                                  const SolverConfig& config) {
  auto s = std::make_shared<Solved>();
  s->kind = "pose";
  s->config = config;
  auto solution = std::make_shared<PoseSolution>(ValueOrThrow(SolvePoseProblem(*problem, config)));
  const PoseComparison comparison = ComparePoseMethods(*problem, config, *solution);
  s->json = PoseResultJson(*problem, *solution, comparison);
  s->mirrored = problem->handedness == Handedness::kMirrored;
  s->bp = solution->ba_problem;
  s->br = solution->ba_result;
  s->input = problem;
  s->pose = solution;
  return s;
}

std::shared_ptr<Solved> SolveJoint(std::shared_ptr<const Problem> problem,
                                   const SolverConfig& config,
                                   bool mrcal_crosscheck) {
  auto s = std::make_shared<Solved>();
  s->kind = "joint";
  s->config = config;
  auto solution =
      std::make_shared<JointSolution>(ValueOrThrow(SolveJointProblem(*problem, config)));
  s->json = JointSolutionToJson(*problem, config, *solution);
  if (mrcal_crosscheck) {
    // A unique work directory under the system's temporary directory ($TMPDIR), as the plots'
    // (report/plots.cc); JointMrcalCrossCheckJson removes it.
    std::error_code ec;
    std::string tmpl =
        (std::filesystem::temp_directory_path(ec) / "carmba_python_mrcal_XXXXXX").string();
    if (ec || !::mkdtemp(tmpl.data())) {
      throw Error("mrcal_crosscheck: cannot create a temporary directory " + tmpl);
    }
    MrcalCrossCheckOptions mrcal_options;
    mrcal_options.work_dir = tmpl;
    s->json["mrcal_crosscheck"] = JointMrcalCrossCheckJson(*problem, *solution, mrcal_options);
  }
  s->bp = std::shared_ptr<const ba::BaProblem>(solution, &solution->ba_problem);
  s->br = std::shared_ptr<const ba::BaResult>(solution, &solution->result);
  s->input = problem;
  s->joint = solution;
  return s;
}

std::shared_ptr<Solved> Solve(const std::string& problem_path,
                              const std::string& config_path,
                              bool mrcal_crosscheck) {
  py::gil_scoped_release release;
  const SolverConfig config = ValueOrThrow(LoadSolverConfig(config_path));
  auto problem = std::make_shared<const Problem>(ValueOrThrow(LoadProblem(problem_path)));
  if (!problem->IsPoseProblem()) return SolveJoint(problem, config, mrcal_crosscheck);
  return SolvePose(problem, config);
}

GeometrySet Geometry(const Solved& s) {
  return s.kind == "joint" ? JointSolutionGeometry(*s.input, *s.joint)
                           : PoseSolutionGeometry(*s.input, *s.pose);
}

// ---- triangulate (cmd_triangulate.cc): pixels {view id: (u, v)} of object views.
py::dict Triangulate(const Solved& s,
                     const py::dict& pixels,
                     double sigma_px,
                     const py::object& covariances,
                     double min_angle_deg) {
  if (s.kind == "pose" &&
      (!s.config.refine || s.config.covariance_algorithm != ba::CovarianceAlgorithm::kSchur)) {
    throw Error(s.config.path + ": triangulation needs the refined solve's covariance "
                "(refine: true, covariance: {algorithm: schur})");
  }
  const ba::BaProblem& bp = s.problem();
  const ba::BaResult& br = s.result_with_covariance();
  analysis::TriangulationOptions topt;
  topt.min_ray_angle_deg = min_angle_deg;
  std::string err;
  if (!topt.Check(&err)) throw Error("min_angle_deg: " + err);
  std::vector<analysis::PixelObservation> obs;
  std::string object_ids;
  std::map<std::string, int> object_view;
  for (size_t v = 0; v < bp.views.size(); ++v) {
    if (bp.views[v].kind != ba::ViewKind::kObject) continue;
    object_view[bp.views[v].id] = static_cast<int>(v);
    object_ids += (object_ids.empty() ? "" : ", ") + bp.views[v].id;
  }
  for (auto item : pixels) {
    const std::string id = py::str(item.first);
    auto it = object_view.find(id);
    if (it == object_view.end()) {
      throw Error("pixels: view '" + id + "' is not an object view of the problem (object views: " +
                  object_ids + ")");
    }
    const auto uv = item.second.cast<std::vector<double>>();
    if (uv.size() != 2) throw Error("pixels['" + id + "']: expected (u, v)");
    analysis::PixelObservation o;
    o.view = it->second;
    o.uv_px = Eigen::Vector2d(uv[0], uv[1]);
    const double sg = sigma_px > 0 ? sigma_px : bp.views[o.view].sigma_px;
    o.covariance_px2 = Eigen::Matrix2d::Identity() * sg * sg;
    if (!covariances.is_none() && covariances.contains(py::str(id))) {
      const auto c = covariances[py::str(id)].cast<std::vector<std::vector<double>>>();
      if (c.size() != 2 || c[0].size() != 2 || c[1].size() != 2) {
        throw Error("covariances['" + id + "']: expected a 2 x 2 pixel covariance (px^2)");
      }
      o.covariance_px2 << c[0][0], c[0][1], c[1][0], c[1][1];
    }
    obs.push_back(o);
  }
  analysis::TriangulatedPoint t;
  {
    py::gil_scoped_release release;
    t = ValueOrThrow(analysis::TriangulatePoint(bp, br, obs, topt));
  }
  // The solve's object frame -> the CT frame (a mirrored pose problem negates y), as the CLI.
  const Eigen::Matrix3d F = Eigen::Vector3d(1, s.mirrored ? -1 : 1, 1).asDiagonal();
  py::dict d;
  d["p_in_ct_mm"] = ToNumpyVector(F * t.p_in_object);
  d["covariance_mm2"] = ToNumpy(F * t.covariance * F);
  d["covariance_pixels_mm2"] = ToNumpy(F * t.covariance_pixels * F);
  d["covariance_solve_mm2"] = ToNumpy(F * t.covariance_solve * F);
  d["covariance_calibration_mm2"] = ToNumpy(F * t.covariance_calibration * F);
  py::dict by_source;
  for (int k = 0; k < ba::kNumSources; ++k) {
    by_source[ba::SourceName(static_cast<ba::Source>(k))] = t.solve_trace_by_source[k];
  }
  by_source["the point's pixels"] = t.covariance_pixels.trace();
  d["variance_by_source_mm2"] = by_source;
  Eigen::MatrixXd res(t.residual_px.size(), 2);
  for (size_t i = 0; i < t.residual_px.size(); ++i) res.row(i) = t.residual_px[i].transpose();
  d["residual_px"] = ToNumpy(res);
  d["max_ray_angle_deg"] = t.max_ray_angle_deg;
  d["rms_px"] = t.rms_px;
  d["rejected"] = std::vector<bool>(t.rejected.begin(), t.rejected.end());
  d["chi2"] = t.chi2;
  d["dof"] = t.dof;
  d["chi2_p_value"] = t.chi2_p_value;
  d["warnings"] = t.warnings;
  return d;
}

py::object Tre(const Solved& s) {
  const auto& tre = s.kind == "joint" ? s.joint->tre : s.pose->tre;
  if (tre) return ToPython(TreJson(*tre));
  const ba::BaResult& r = s.result_with_covariance();
  analysis::TreResult t;
  {
    py::gil_scoped_release release;
    t = ValueOrThrow(analysis::LeaveOneMarkerOut(s.problem(), r, s.config.ToBaOptions()));
  }
  return ToPython(TreJson(t));
}

// ---- export-geometry: from a Result or a geometry.json path (or a solve's output directory).
py::dict ExportGeometry(const py::object& source,
                        const py::object& out,
                        const std::string& format,
                        double sdd_mm,
                        bool force) {
  GeometrySet set;
  std::string where;
  if (py::isinstance<Solved>(source)) {
    set = Geometry(source.cast<const Solved&>());
    where = "result";
  } else {
    const std::string p = py::str(source);
    where = IsDirectory(p) ? JoinPath(p, "geometry.json") : p;
    set = ValueOrThrow(ReadGeometryJson(where));
  }
  const GeometryExport e = ValueOrThrow(ExportGeometryFiles(set, where, format, sdd_mm));
  if (!out.is_none()) {
    const std::string dir = py::str(out);
    ThrowIfError(CheckOutputDir(dir, "out", force, "pass force=True to write over it"));
    StagedOutputDir staged(dir);
    Status st = staged.Begin();
    for (const auto& [name, text] : e.files) {
      if (st.ok()) st = MakeParentDirs(JoinPath(staged.path(), name));
      if (st.ok()) st = WriteFileAtomic(JoinPath(staged.path(), name), text);
    }
    if (st.ok()) st = staged.Commit(/*replace_all=*/false);
    ThrowIfError(st);
  }
  py::dict files;
  for (const auto& [name, text] : e.files) files[py::str(name)] = text;
  return files;
}

py::object OptionalMatrix(const std::optional<Matrix6>& m) {
  return m ? py::object(ToNumpy(*m)) : py::object(py::none());
}

}  // namespace

void BindSolve(py::module_& m) {
  py::class_<View>(m,
                   "View",
                   "One view of a solve: pose cam_from_object (object view) or cam_from_plate "
                   "(plate view) = [rx, ry, rz (rad, Rodrigues), tx, ty, tz (mm)], "
                   "p_in_cam = R(r) p + t, and its 6 x 6 covariance in that order.")
      .def_readonly("id", &View::id)
      .def_readonly("kind", &View::kind)
      .def_readonly("group", &View::group)
      .def_property_readonly("pose", [](const View& v) { return ToNumpyVector(v.pose); })
      .def_property_readonly("rvec", [](const View& v) { return ToNumpyVector(v.pose.head<3>()); })
      .def_property_readonly("t_mm", [](const View& v) { return ToNumpyVector(v.pose.tail<3>()); })
      .def_property_readonly("covariance_6x6",
                             [](const View& v) { return OptionalMatrix(v.covariance); })
      .def_property_readonly("sigma_rotation_deg",
                             [](const View& v) { return ToNumpyVector(v.sigma_rotation_deg); })
      .def_property_readonly("sigma_translation_mm",
                             [](const View& v) { return ToNumpyVector(v.sigma_translation_mm); })
      .def_readonly("rms_px", &View::rms_px)
      .def_readonly("num_observations", &View::num_observations)
      .def("__repr__", [](const View& v) { return "carmba.View(" + v.kind + " '" + v.id + "')"; });

  py::class_<Intrinsics>(m, "Intrinsics",
                         "One intrinsics group: values over names (fx fy cx cy k1 k2 p1 p2 k3, or "
                         "a smooth model's coefficients) and their covariance in that order.")
      .def_readonly("group", &Intrinsics::group)
      .def_readonly("names", &Intrinsics::names)
      .def_property_readonly("values", [](const Intrinsics& i) { return ToNumpyVector(i.values); })
      .def_property_readonly("covariance", [](const Intrinsics& i) {
        return i.covariance.size() ? py::object(ToNumpy(i.covariance)) : py::object(py::none());
      })
      .def_readonly("uncertainty", &Intrinsics::uncertainty)
      .def_readonly("width", &Intrinsics::width)
      .def_readonly("height", &Intrinsics::height);

  py::class_<Solved, std::shared_ptr<Solved>>(m, "Result", "A solved pose or joint problem.")
      .def_readonly("kind", &Solved::kind)
      .def_property_readonly(
          "views", [](const Solved& s) { return s.kind == "joint" ? JointViews(s) : PoseViews(s); })
      .def_property_readonly("intrinsics",
                             [](const Solved& s) {
                               return s.kind == "joint" ? JointIntrinsics(s) : PoseIntrinsics(s);
                             })
      .def_property_readonly(
          "blocks",
          [](const Solved& s) {
            std::vector<std::string> names;
            for (const auto& [n, b] : BlockNames(s.problem(), *s.result().layout))
              names.push_back(n);
            return names;
          })
      .def(
          "block_parameters",
          [](const Solved& s, const std::string& name) {
            return BlockParameters(s, FindBlock(s, name));
          },
          py::arg("block"))
      .def(
          "covariance",
          [](const Solved& s, const std::string& a, const py::object& b) {
            return ToNumpy(CrossCovariance(s, a, b.is_none() ? a : std::string(py::str(b))));
          },
          py::arg("block_a"),
          py::arg("block_b") = py::none(),
          "Cov(block_a, block_b): rows over block_a's parameters, columns over block_b's "
          "(block_parameters), ambient (held parameters as zero rows/columns).")
      .def_property_readonly("error_budget", &ErrorBudget)
      .def_property_readonly("relative_poses", &RelativePoses)
      .def_property_readonly("statistics", &Statistics)
      .def_property_readonly(
          "variance_components",
          [](const Solved& s) {
            return ToPython(s.json.value("variance_components", nlohmann::json()));
          })
      .def_property_readonly("warnings",
                             [](const Solved& s) {
                               return ToPython(s.json.value("warnings", nlohmann::json::array()));
                             })
      .def_property_readonly("tre",
                             [](const Solved& s) {
                               const auto& tre = s.kind == "joint" ? s.joint->tre : s.pose->tre;
                               return tre ? ToPython(TreJson(*tre)) : py::object(py::none());
                             })
      .def(
          "to_json",
          [](const Solved& s) { return s.json.dump(2) + "\n"; },
          "result.json's text as `carmba solve` writes it")
      .def(
          "geometry",
          [](const Solved& s) { return GeometryToJson(Geometry(s)).dump(2) + "\n"; },
          "geometry.json's text as `carmba solve` writes it")
      .def("__repr__", [](const Solved& s) {
        return "carmba.Result(" + s.kind + ", " + std::to_string(s.bp ? s.bp->views.size() : 0) +
               " views)";
      });

  m.def("solve", &Solve, py::arg("problem"), py::arg("config"),
        py::arg("mrcal_crosscheck") = false,
        "Solves a pose or joint problem file with a solver config, as `carmba solve` does. "
        "mrcal_crosscheck=True (joint problems) runs the mrcal cross-check through "
        "/usr/bin/python3 into to_json()'s 'mrcal_crosscheck', as the command does.");
  m.def("triangulate", &Triangulate, py::arg("result"), py::arg("pixels"),
        py::arg("sigma_px") = 0.0, py::arg("covariances") = py::none(),
        py::arg("min_angle_deg") = 5.0,
        "Triangulates one point from pixels {object view id: (u, v)} of a solved result, as "
        "`carmba triangulate --pixels`: position and 3 x 3 covariance in the CT frame (mm).");
  m.def(
      "tre",
      &Tre,
      py::arg("result"),
      "The leave-one-marker-out target registration error (analysis/tre.h): the solve's own when "
      "its config had tre: true, else computed now with the same options.");
  m.def("export_geometry", &ExportGeometry, py::arg("source"), py::arg("out") = py::none(),
        py::arg("format") = "all", py::arg("sdd_mm") = 0.0, py::arg("force") = false,
        "The files `carmba export-geometry` writes ({name: text}) from a Result or a "
        "geometry.json path (or a solve's output directory); written into `out` when given.");
}

}  // namespace carmba::python
