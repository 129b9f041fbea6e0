// Flags shared by several subcommands. gflags flags are process-global, so a flag name may be
// DEFINEd only once in the whole `carmba` binary: a subcommand that needs one of these includes
// this header (DECLARE) instead of DEFINE-ing it again, and lists the shared flags it uses with
// CARMBA_COMMAND_FLAGS(name, "out,config") so that its --help shows them and other commands'
// use of them is rejected. Flags used by one command only are DEFINEd in that command's file.
#pragma once

#include <gflags/gflags.h>

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "util/progress.h"
#include "util/status.h"

DECLARE_string(out);      // output directory or file
DECLARE_string(config);   // solver/calibration configuration YAML
DECLARE_string(problem);  // problem YAML
DECLARE_string(images);   // directory or glob of images
DECLARE_string(camera);   // camera.json (or a joint result.json's intrinsics)
DECLARE_string(pattern);  // calibration pattern: circles | acircles | chessboard
DECLARE_int32(rows);      // pattern rows
DECLARE_int32(cols);      // pattern columns
DECLARE_double(spacing_mm);  // grid pitch in mm (0: from the problem / observations, else 20)
DECLARE_uint64(seed);     // random seed
DECLARE_int32(jobs);      // parallel jobs (0 = all cores)
DECLARE_bool(force);      // write over an existing result in --out
DECLARE_bool(verbose);    // progress on stderr (every command has it)
DECLARE_bool(plots);      // report.html's matplotlib plots (--no-plots: none, no Python)
DECLARE_bool(mrcal);      // the mrcal cross-check (--no-mrcal: skipped)
DECLARE_string(mrcal_python);  // the Python with mrcal (calibrate, solve)
DECLARE_string(detection);     // detection options YAML (pose: markers; calibrate, detect: grid)
DECLARE_double(marker_diameter_mm);  // marker / bead diameter (pose, track)

namespace carmba::cli {
// The numeric flags checked against their plausible ranges (util/plausible.h); each returns false
// with `error` naming the flag, the range and the value.
// --spacing_mm: 0 (not given) or plausible::kGridSpacingMm.
bool CheckSpacingFlag(std::string* error);
// --rows and --cols (plausible::kGridRowsCols), and --spacing_mm.
bool CheckGridFlags(std::string* error);
// --jobs: plausible::kJobs (0 = all cores).
bool CheckJobsFlag(std::string* error);

// --out, checked before any work, the same way for every command (util/file_util.h): missing
// parent directories are fine (they are created when the result is written); an existing result
// (a non-empty directory, an existing file) is refused unless --force (or `also_allowed`, e.g.
// study's --resume).
Status CheckOutDir(bool also_allowed = false,
                   const std::string& how_to_override = "pass --force to write over it");
Status CheckOutFile();

// An input of a command: `what` names it in messages ("--images", "--problem key 'images'"),
// `path` is a file, a directory, a glob or `file.dcm#frameN`.
struct InputPath {
  std::string what;
  std::string path;
};
// The flags that name inputs (files, directories, globs; --shards a comma-separated list of
// them), with underscores. Every command's --out is checked against those it has before it runs
// (main.cc), so a new input flag goes here.
const std::vector<std::string>& InputFlagNames();
// The inputs named by `flag_names` that are in InputFlagNames() and set (--shards split at ',').
std::vector<InputPath> InputsOfFlags(const std::vector<std::string>& flag_names);
// InputsOfFlags and, for each input that is a YAML file (a problem, config or study file), the
// files it names (study/study_inputs.h FilesNamedInYaml), as "a file named in --problem P".
std::vector<InputPath> InputsOfFlagsAndFilesTheyName(const std::vector<std::string>& flag_names);
// --out is not, and does not contain, any of `inputs` (util/file_util.h CheckOutputIsNotInput),
// with --force or not. A usage error (kExitUsage). main.cc checks the flags' inputs; a command
// that reads more inputs from a file (a problem's images) checks those once it has read it.
Status CheckOutIsNoInput(const std::vector<InputPath>& inputs);

// Progress of `total` items of `unit` for the command `label`: a bar when stderr is a terminal,
// else one line per item with --verbose, else nothing (util/progress.h).
std::unique_ptr<Progress> MakeProgress(const std::string& label,
                                       int total,
                                       const std::string& unit);
// For LoadPlateViews' `detecting` (problem/problem.h): given the number of images, starts the
// step "detecting the grid in N images" and a progress bar labelled `label` (held in *progress
// until the caller resets it), and returns its per-image callback.
std::function<ProgressFn(int)> GridDetectionProgress(const std::string& command,
                                                     const std::string& label,
                                                     std::unique_ptr<Progress>* progress);
// With --verbose, the command's steps and their wall times on stderr: "carmba <command>: <what>"
// when a step starts, and "carmba <command>: <what>: 0.123 s" when the next one starts or the
// command ends (EndSteps).
void Step(const std::string& command, const std::string& what);
// With --verbose: ends the last step and prints "carmba <command>: total 1.234 s" (the time since
// the process started). main() calls it after every command.
void EndSteps(const std::string& command);
}  // namespace carmba::cli
