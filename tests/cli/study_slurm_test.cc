// scripts/slurm_study.sh end to end, with a stand-in `sbatch` that executes what it is given (the
// array tasks one after the other with SLURM_ARRAY_TASK_ID set, then the --wrap merge command):
// the merged result of the Slurm shards equals a single-machine run of the whole study.
#include <gtest/gtest.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include <fstream>
#include <string>

#include "scratch.h"
#include "util/file_util.h"

namespace carmba {
namespace {

const std::string kSlurmSrc = CARMBA_SOURCE_DIR;
const std::string kSlurmBin = CARMBA_BIN;

std::string ReadSlurmFile(const std::string& path) {
  StatusOr<std::string> s = ReadFile(path);
  return s.ok() ? *s : "<missing " + path + ">";
}

int SlurmShell(const std::string& cmd) {
  const int status = std::system(cmd.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(StudySlurmTest, JobArrayShardsMergeToTheWholeStudy) {
  const test::ScratchDir scratch("slurm");  // removed with its files when the test ends
  const std::string& dir = scratch.path();
  ASSERT_TRUE(MakeDirs(dir + "/fakebin").ok());
  const std::string sbatch = dir + "/fakebin/sbatch";
  std::ofstream(sbatch) << R"(#!/usr/bin/env bash
# Stand-in for Slurm's sbatch: runs the job at once and prints a job id (--parsable).
echo "$*" >> "$(dirname "$0")/calls.log"
array=""; wrap=""; cmd=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --array=*) array="${1#--array=}" ;;
    --wrap=*) wrap="${1#--wrap=}" ;;
    --*) ;;
    *) cmd=("$@"); break ;;
  esac
  shift
done
if [[ -n "$array" ]]; then
  for ((k = ${array%-*}; k <= ${array#*-}; k++)); do
    SLURM_ARRAY_TASK_ID=$k SLURM_CPUS_PER_TASK=1 "${cmd[@]}" > /dev/null || exit 1
  done
elif [[ -n "$wrap" ]]; then
  bash -c "$wrap" > /dev/null || exit 1
fi
echo $RANDOM
)";
  ::chmod(sbatch.c_str(), 0755);
  const std::string study = dir + "/study.yaml";
  std::ofstream(study)
      << "name: slurm\ntrials: 5\nproblems:\n  - name: sim\n    synthetic: {camera: " << kSlurmSrc
      << "/data/thesis/camera.json, markers: thesis}\nconfigs:\n"
      << "  - {name: c, file: " << kSlurmSrc << "/configs/posit_ba_analytic.yaml}\n"
      << "sweeps:\n  pixel_noise_px: [0.2, 0.6, 1.0]\n";
  const std::string log = " > '" + dir + "/log.txt' 2>&1";
  ASSERT_EQ(
      SlurmShell("PATH='" + dir + "/fakebin':\"$PATH\" CARMBA='" + kSlurmBin + "' '" + kSlurmSrc +
                 "/scripts/slurm_study.sh' '" + study + "' '" + dir + "/out' 3" + log),
      0)
      << ReadSlurmFile(dir + "/log.txt");
  for (int k = 1; k <= 3; ++k) {
    EXPECT_TRUE(FileExists(dir + "/out/shard-" + std::to_string(k) + "/runs.jsonl")) << k;
  }
  ASSERT_EQ(SlurmShell("'" + kSlurmBin + "' study --no-plots --study='" + study + "' --out='" +
                       dir + "/whole'" + log),
            0)
      << ReadSlurmFile(dir + "/log.txt");
  EXPECT_EQ(ReadSlurmFile(dir + "/out/merged/summary.csv"),
            ReadSlurmFile(dir + "/whole/summary.csv"));
  // The array tasks draw no plots (--no-plots); the merge draws those of all runs.
  EXPECT_NE(ReadSlurmFile(dir + "/out/shard-1/report.html").find("not drawn (--no-plots)"),
            std::string::npos);
  const std::string merged = ReadSlurmFile(dir + "/out/merged/report.html");
  EXPECT_NE(merged.find("data-plot=\"error-vs-noise"), std::string::npos);
  EXPECT_EQ(merged.find("not drawn (--no-plots)"), std::string::npos);
  const std::string calls = ReadSlurmFile(dir + "/fakebin/calls.log");
  EXPECT_NE(calls.find("--array=1-3"), std::string::npos) << calls;
  EXPECT_NE(calls.find("--dependency=afterok:"), std::string::npos) << calls;
  // Usage errors are reported before anything is submitted.
  EXPECT_EQ(SlurmShell("'" + kSlurmSrc + "/scripts/slurm_study.sh' '" + study + "' '" + dir +
                       "/x' zero" + log),
            2);
  EXPECT_NE(ReadSlurmFile(dir + "/log.txt").find("NUM_SHARDS must be a positive integer"),
            std::string::npos);
}

}  // namespace
}  // namespace carmba
