// The keys and columns carmba's readers accept, recorded as they read, so that the documentation
// of the file formats (src/docs/formats.md) is checked against the readers themselves
// (tests/cli/docs_formats_test.cc) rather than against a second hand-written list.
//
// Recording is off unless a test calls EnableAcceptedKeyRecording() or the environment variable
// CARMBA_ACCEPTED_KEYS names a file: then every process linking this writes, at exit, one line
// "FILE<TAB>KEY" per key it recorded (for commands whose parsers live in the CLI).
//
// What is recorded:
//   * YAML (util/yaml_reader.h): every key a parser asked for in a map that finished without an
//     error -- present in the file or not -- as a dotted path with list indices written `[]`
//     (`views[].primary_deg`); a map whose keys are names the user chooses (materials, sweeps)
//     records `<placeholder>` instead (`materials.<material>`).
//   * CSV (util/csv.h): every column a reader looked up, by name.
#pragma once

#include <map>
#include <set>
#include <string>

namespace carmba {

void EnableAcceptedKeyRecording();
bool AcceptedKeyRecordingEnabled();
// Records `key` as accepted in `file` (no-op unless recording is enabled).
void RecordAcceptedKey(const std::string& file, const std::string& key);
// The keys recorded so far, by file.
std::map<std::string, std::set<std::string>> AcceptedKeys();
void ClearAcceptedKeys();

}  // namespace carmba
