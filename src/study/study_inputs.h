// What a study's runs read, and the study fingerprint built from it (DIR/study.json): resume
// and study-merge refuse a directory whose study differs, naming what changed.
//
// The input files of a study are found from its entries, whatever the kind of run:
//   * every problem's and config's `file`;
//   * every string inside a problem's `synthetic` or `options` mapping (and a config's `options`)
//     that names an existing file, directory or glob pattern relative to the study file
//     (`camera: camera.json`, a scene file, an image directory);
//   * inside each YAML file found so far, every string value that names an existing file,
//     directory or glob pattern relative to that file (a problem's markers and observations CSVs,
//     its camera.json, its images), recursively (YAML files up to 4 levels deep).
// A directory or glob stands for its regular files (util/file_util.h ListFiles). A string that
// names nothing on disk is not an input (e.g. `markers: thesis`); a `file` that is missing is
// one, hashed as "missing" (its runs fail; creating it later changes the fingerprint).
//
// The fingerprint hashes (FNV-1a 64) carmba's version, the run list (keys and seeds), the
// study's entries (problem and config names, resolved paths, synthetic and options mappings,
// trials) and the content of every input file, and ends in "-<number of runs>".
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "study/study_spec.h"

namespace carmba {

struct StudyInput {
  std::string path;     // as resolved: relative to the working directory, or absolute
  std::string hash;     // FNV-1a 64 of the content, 16 hex digits; "missing" when unreadable
  std::string used_by;  // the first entry that reads it, e.g. "config 'sqpnp_ba'"
};

// The input files of a study, sorted by path (each once).
std::vector<StudyInput> StudyInputFiles(const StudySpec& spec);

// The files a YAML file names, found as above (its string values naming an existing file,
// directory or glob relative to it, recursively through the YAML files named; a directory or glob
// stands for its files), without the YAML file itself and without hashing: the inputs a problem,
// config or study file makes a command read (main.cc checks --out against them).
std::vector<std::string> FilesNamedInYaml(const std::string& yaml_path);

// FNV-1a 64 of a file's content as 16 hex digits, or "missing" when it cannot be read.
std::string FileContentHash(const std::string& path);

// The parts of a study's identity, as written to DIR/study.json (see run_store.h
// StudyInfoJson): "carmba_version", "runs_hash", "entries_hash", "inputs" (path, hash,
// used_by) and "fingerprint", the hash of them all.
nlohmann::json StudyIdentityJson(const StudySpec& spec,
                                 const std::vector<RunSpec>& all_runs,
                                 const std::vector<StudyInput>& inputs);

// What differs between the identities of two study.json objects `was` and `now`, in one line
// naming the first differing part (an input file first: "configs/a.yaml (config 'a') has
// different content"), or "" when their fingerprints are equal.
std::string DescribeStudyChange(const nlohmann::json& was, const nlohmann::json& now);

}  // namespace carmba
