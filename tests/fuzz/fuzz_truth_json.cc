// libFuzzer harness: the truth.json readers, through the problem loaders that call them (they are
// internal to problem/pose_problem_io.cc and joint/joint_problem_io.cc): a fixed, valid pose
// problem (the thesis's, without its reference tables) and a fixed, valid object-only joint
// problem both name `truth: truth.json`, and the input is that file.
#include <cstdio>
#include <cstdlib>

#include "fuzz_util.h"
#include "joint/joint_problem.h"
#include "problem/pose_problem.h"

namespace {

std::string pose_yaml, joint_yaml;

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  using carmba::fuzz::WriteText;
  pose_yaml = WriteText("p/truth_pose.yaml",
                        "name: truth_pose\n"
                        "camera: ../data/thesis/camera.json\n"
                        "sigma_px: 1.0\n"
                        "markers: {file: ../data/thesis/projections_table_5_2.csv, id_column: "
                        "marker, columns: [x, y, z], sigma_mm: 0.3}\n"
                        "observations: {file: ../data/thesis/projections_table_5_2.csv, format: "
                        "wide, marker_column: marker}\n"
                        "views: [0, 10, 30, 50, 90]\n"
                        "truth: truth.json\n");
  WriteText("p/objects.csv",
            "view,marker,u_px,v_px\n"
            "a,1,100,100\na,2,200,110\na,3,190,220\na,4,90,210\n");
  WriteText("p/fiducials.csv",
            "id,x_mm,y_mm,z_mm\n1,0,0,0\n2,50,0,0\n3,50,50,0\n4,0,50,10\n");
  joint_yaml = WriteText("p/truth_joint.yaml",
                         "name: truth_joint\n"
                         "camera: ../data/thesis/camera.json\n"
                         "object_views: {observations: objects.csv, sigma_px: 0.3}\n"
                         "fiducials: {file: fiducials.csv, sigma_mm: 0.3}\n"
                         "truth: truth.json\n");
  // Self-check: with a valid truth.json both loaders succeed, so the fuzzed bytes reach the
  // truth readers (a change to the loaders that made them fail earlier would stop this harness).
  WriteText("p/truth.json",
            "{\"views\": [{\"id\": 0, \"rvec\": [0, 0, 0], \"t_mm\": [0, 0, 1000]}],\n"
            " \"object_views\": [{\"id\": \"a\", \"rvec\": [0, 0, 0], \"t_mm\": [0, 0, 1000]}]}\n");
  auto pose = carmba::LoadPoseProblem(pose_yaml);
  auto joint = carmba::LoadJointProblem(joint_yaml);
  if (!pose.ok() || !joint.ok()) {
    std::fprintf(stderr, "fuzz_truth_json: the fixed problems do not load: %s / %s\n",
                 pose.ok() ? "ok" : pose.status().message().c_str(),
                 joint.ok() ? "ok" : joint.status().message().c_str());
    std::abort();
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  carmba::fuzz::WriteInput("p/truth.json", data, size);
  (void)carmba::LoadPoseProblem(pose_yaml);
  (void)carmba::LoadJointProblem(joint_yaml);
  return 0;
}
