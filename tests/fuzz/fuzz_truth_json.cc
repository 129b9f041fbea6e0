// Fuzz target `truth_json` (fuzz_main.cc): the truth.json reader, through the problem loader that
// calls it (it is internal to problem/problem_io.cc): a fixed, valid problem names `truth:
// truth.json`, and the input is that file.
#include <cstdio>
#include <cstdlib>

#include "fuzz_target.h"
#include "fuzz_util.h"
#include "problem/problem.h"

namespace {

std::string truth_problem_yaml;

int InitTruthJson() {
  using carmba::fuzz::WriteText;
  WriteText("p/objects.csv",
            "view,marker,u_px,v_px\n"
            "a,1,100,100\na,2,200,110\na,3,190,220\na,4,90,210\n");
  WriteText("p/fiducials.csv",
            "id,x_mm,y_mm,z_mm\n1,0,0,0\n2,50,0,0\n3,50,50,0\n4,0,50,10\n");
  truth_problem_yaml = WriteText("p/truth_problem.yaml",
                                 "name: truth_problem\n"
                                 "camera: ../data/thesis/camera.json\n"
                                 "object_views: {observations: objects.csv, sigma_px: 0.3}\n"
                                 "fiducials: {file: fiducials.csv, sigma_mm: 0.3}\n"
                                 "truth: truth.json\n");
  // Self-check: with a valid truth.json the loader succeeds, so the fuzzed bytes reach the truth
  // reader (a change to the loader that made it fail earlier would stop this harness).
  WriteText("p/truth.json",
            "{\"views\": [{\"id\": 0, \"rvec\": [0, 0, 0], \"t_mm\": [0, 0, 1000]}],\n"
            " \"object_views\": [{\"id\": \"a\", \"rvec\": [0, 0, 0], \"t_mm\": [0, 0, 1000]}]}\n");
  auto problem = carmba::LoadProblem(truth_problem_yaml);
  if (!problem.ok()) {
    std::fprintf(stderr, "fuzz_truth_json: the fixed problem does not load: %s\n",
                 problem.status().message().c_str());
    std::abort();
  }
  return 0;
}

int FuzzTruthJson(const uint8_t* data, size_t size) {
  carmba::fuzz::WriteInput("p/truth.json", data, size);
  (void)carmba::LoadProblem(truth_problem_yaml);
  return 0;
}

}  // namespace

CARMBA_FUZZ_TARGET(truth_json, FuzzTruthJson, InitTruthJson)
