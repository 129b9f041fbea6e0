// Accuracy studies: which problems, which solver configurations, which sweep values and how many
// seeded Monte Carlo trials, and the deterministic list of runs they expand to.
//
// A study file (configs/studies/NAME.yaml):
//
//   name: noise_sweep                # optional, defaults to the file's base name
//   trials: 20                       # Monte Carlo trials per (problem, config, sweep point), >= 1
//   base_seed: 1                     # non-negative integer
//   allow_failures: 0.05             # optional: share of runs that may fail (default 0: any
//                                    # failed run makes `carmba study` exit 1)
//   problems:                        # >= 1 entries, unique names
//     - name: thesis_table_5_2
//       file: ../../problems/thesis_table_5_2.yaml    # relative to the study file
//     - name: sim_block
//       synthetic: { ... }           # a mapping handed to the run function (e.g. a simulator spec)
//       trials: 5                    # optional: overrides the study's trials for this problem
//   configs:                         # >= 1 entries, unique names
//     - name: sqpnp_ba
//       file: ../solvers/sqpnp_ba.yaml
//   sweeps:                          # optional; the runs take the Cartesian product of the lists,
//     pixel_noise_px: [0.1, 0.3, 1]  # in the order the keys are written
//     ct_noise_mm: [0.05, 0.5]
//
// A problem has a `file` or a `synthetic` mapping (exactly one) and an optional `options`
// mapping; a config has a `file` and an optional `options` mapping. The run function interprets
// `synthetic` and `options` (and rejects what it does not understand, as a run error). Files are
// NOT read here: a missing or malformed problem or config file is an error of the runs that use it
// (recorded, the study goes on), not of the study.
//
// Runs are enumerated problem-major: for each problem, each config, each sweep point, each trial.
// A run's key is a stable string, e.g.
//   sim_block|sqpnp_ba|pixel_noise_px=0.3,ct_noise_mm=0.05|trial=7
// and its seed is derived from base_seed and the run's DATA key (the key without the config), so
// every config of a study sees the same noisy data in the same trial (paired comparison), and the
// seed never depends on the thread or the shard that executes the run.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "util/plausible.h"
#include "util/status.h"

namespace carmba {

// The share of a study's runs allowed to fail (`allow_failures`, --allow-failures): a fraction,
// 0 (any failed run fails the study) .. 1 (failures never do). (Not a plausibility bound of a
// measurement, so not in util/plausible.h.)
inline constexpr PlausibleRange kFailureFraction{0, 1, ""};

struct StudyProblem {
  std::string name;
  std::string file;           // resolved path (relative to the study file's directory), or empty
  nlohmann::json synthetic;   // the `synthetic` mapping as JSON, or null
  nlohmann::json options;     // the optional `options` mapping as JSON, or null
  std::string base_dir;       // the study file's directory (for paths inside `synthetic`)
  int trials = 0;             // optional per-problem trial count (0: the study's `trials`), e.g.
                              // 1 for measured data solved as they are
};

struct StudyConfig {
  std::string name;
  std::string file;         // resolved path
  nlohmann::json options;   // the optional `options` mapping as JSON, or null
};

// One swept variable and its values, in file order.
struct StudySweep {
  std::string name;
  std::vector<double> values;
};

struct StudySpec {
  std::string name;
  std::string path;  // the study file, for messages
  int trials = 1;
  uint64_t base_seed = 0;
  double allow_failures = 0;  // share of runs that may fail before the study fails (0..1)
  std::vector<StudyProblem> problems;
  std::vector<StudyConfig> configs;
  std::vector<StudySweep> sweeps;

  // Unique non-empty names, trials >= 1, finite sweep values, non-empty lists. Names may not
  // contain '|', '=' or ',' (they build run keys).
  bool Check(std::string* error) const;
};

// A sweep point: the swept variables and their values, in the study's sweep order.
using SweepPoint = std::vector<std::pair<std::string, double>>;

struct RunSpec {
  int index = 0;            // position in the study's enumeration order
  std::string key;          // stable unique key (see above)
  int problem_index = 0;
  int config_index = 0;
  int sweep_index = 0;      // index of the sweep point (0 when there are no sweeps)
  const StudyProblem* problem = nullptr;
  const StudyConfig* config = nullptr;
  SweepPoint sweep;
  int trial = 0;
  uint64_t seed = 0;

  // The swept value of `name`, or `fallback` when the study does not sweep it.
  double SweepValue(const std::string& name, double fallback) const;
};

// Reads and checks a study file. Errors name the file, line and key.
StatusOr<StudySpec> LoadStudySpec(const std::string& path);

// All runs of a study, in enumeration order. The returned specs point into `spec`.
std::vector<RunSpec> EnumerateRuns(const StudySpec& spec);

// The sweep points of a study in order (one empty point when there are no sweeps).
std::vector<SweepPoint> SweepPoints(const StudySpec& spec);

// "pixel_noise_px=0.3,ct_noise_mm=0.05" ("-" for the empty point). Values use %.12g.
std::string SweepPointLabel(const SweepPoint& point);

// The deterministic seed of a run: SplitMix64 of base_seed and the FNV-1a hash of `data_key`.
uint64_t DeriveSeed(uint64_t base_seed, const std::string& data_key);

// 64-bit FNV-1a, for fingerprints and seeds.
uint64_t Fnv1a64(const std::string& s);

// The runs of shard `k` of `n` (1 <= k <= n): those whose enumeration index i has i % n == k - 1.
// The shards partition the runs and interleave the groups, so each shard takes a similar load.
std::vector<RunSpec> ShardRuns(const std::vector<RunSpec>& runs, int k, int n);

// Parses "K/N" (1 <= K <= N). Error names the flag value and what was expected.
Status ParseShard(const std::string& text, int* k, int* n);

}  // namespace carmba
