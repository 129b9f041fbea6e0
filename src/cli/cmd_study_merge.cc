// `carmba study-merge`: combine the output directories of `carmba study --shard K/N` runs (e.g.
// the tasks of a Slurm job array, scripts/slurm_study.sh) into one study directory with
// runs.jsonl, summaries and report, identical to those of an unsharded run.
#include <gflags/gflags.h>
#include <glob.h>

#include <algorithm>
#include <cstdio>
#include <iostream>
#include <sstream>

#include "cli/command.h"
#include "cli/common_flags.h"
#include "study/runner.h"
#include "util/file_util.h"

DEFINE_string(shards, "", "Shard output directories: a comma-separated list, each item a "
                          "directory or a glob pattern (quoted), e.g. 'out/shard-*'.");
DEFINE_bool(allow_missing, false, "Merge even when some runs of the study are in no shard.");

namespace {

bool HasGlobChars(const std::string& s) { return s.find_first_of("*?[") != std::string::npos; }

int RunStudyMerge() {
  using namespace carmba;
  // --shards and --out are required (checked before this runs: cli/command.h).
  if (const Status s = cli::CheckOutDir(); !s.ok()) return cli::Fail("study-merge", s);
  std::vector<std::string> dirs;
  std::stringstream ss(FLAGS_shards);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (item.empty()) continue;
    if (!HasGlobChars(item)) {
      dirs.push_back(item);
      continue;
    }
    glob_t g;
    std::vector<std::string> matches;
    if (::glob(item.c_str(), GLOB_ONLYDIR | GLOB_MARK, nullptr, &g) == 0) {
      for (size_t i = 0; i < g.gl_pathc; ++i) {
        std::string m = g.gl_pathv[i];
        if (!m.empty() && m.back() == '/') matches.push_back(m.substr(0, m.size() - 1));
      }
    }
    globfree(&g);
    if (matches.empty()) {
      return cli::Fail("study-merge", "--shards item '" + item + "': matches no directory");
    }
    std::sort(matches.begin(), matches.end());
    dirs.insert(dirs.end(), matches.begin(), matches.end());
  }
  int merged = 0, missing = 0;
  // Merged into a staging directory and moved into place: all files or none (util/file_util.h).
  std::string report_warning;
  StagedOutputDir staged(FLAGS_out);
  Status s = staged.Begin();
  if (s.ok()) {
    cli::Step("study-merge", "merging " + std::to_string(dirs.size()) + " shards");
    s = MergeStudyShards(dirs, staged.path(), /*write_report=*/true, FLAGS_allow_missing, &merged,
                         &missing, &report_warning, FLAGS_plots);
  }
  if (s.ok()) s = staged.Commit(/*replace_all=*/false);
  if (!s.ok()) return cli::Fail("study-merge", s);
  std::printf("merged %d runs from %zu shard directories into %s\n", merged, dirs.size(),
              FLAGS_out.c_str());
  if (!report_warning.empty()) {
    std::cerr << "carmba study-merge: warning: " << report_warning << std::endl;
  }
  if (missing > 0) {
    std::cerr << "carmba study-merge: warning: " << missing << " runs of the study are missing"
              << std::endl;
  }
  return 0;
}

const bool kStudyMergeRegistered [[maybe_unused]] = carmba::cli::RegisterCommand(
    "study-merge", "Combine the shard directories of 'carmba study --shard K/N'.", __FILE__,
    RunStudyMerge);
const bool kStudyMergeFlags [[maybe_unused]] =
    carmba::cli::RegisterCommandFlags("study-merge", "out,force,plots");
const bool kStudyMergeRequired [[maybe_unused]] =
    carmba::cli::RegisterRequiredFlags("study-merge", "shards,out");

}  // namespace
