// The `carmba` command's subcommand registry.
//
// Each subcommand lives in its own file src/cli/cmd_<name>.cc, defines its gflags there, and
// registers itself:
//
//   DEFINE_string(problem, "", "Problem YAML file (what is estimated from which data).");
//   static int RunSolve() { ... return 0; }
//   CARMBA_REGISTER_COMMAND(solve, "Solve a pose problem ...", RunSolve);
//
// `carmba <cmd> --help` (or `carmba help <cmd>`) lists the flags defined in that command's file
// plus the shared flags (cli/common_flags.h) it declares with CARMBA_COMMAND_FLAGS(name,
// "out,config"), and marks those it declares required with CARMBA_REQUIRED_FLAGS(name,
// "problem,config,out"): a required flag left out (or empty) is an error before the command
// runs, so commands do not check them again. Flag names are shown with dashes. A flag DEFINEd
// in two files breaks the link (gflags flags are global): shared names (--out, --config,
// --problem, --images, --camera, --pattern, --rows, --cols, --seed, --jobs) come from
// common_flags.h.
// A flag that belongs to another subcommand, or a shared flag the command does not list, is
// rejected. Library code never reads FLAGS_*.
#pragma once

#include <string>
#include <vector>

#include "util/status.h"

namespace carmba::cli {

struct Command {
  std::string name;
  std::string summary;
  std::string file;  // the source file defining the command and its flags
  int (*run)();
};

bool RegisterCommand(const char* name, const char* summary, const char* file, int (*run)());
const std::vector<Command>& Commands();
bool RegisterCommandFlags(const char* name, const char* shared_flags_csv);
bool RegisterRequiredFlags(const char* name, const char* required_flags_csv);
// The shared flags a command declared it uses (empty if it declared none), and its required
// flags (own or shared), with underscores.
std::vector<std::string> CommandSharedFlags(const std::string& name);
std::vector<std::string> CommandRequiredFlags(const std::string& name);

// `carmba help` and `carmba help <cmd>` / `carmba <cmd> --help`.
std::string UsageText();
std::string CommandHelpText(const Command& cmd);
// The arguments of `cmd` as gflags reads them: flag names with underscores, `--no-x` / `--no_x`
// as `--nox`. Error (one line, with the closest flag name) for a flag `cmd` does not have.
Status NormalizeFlags(const Command& cmd,
                      const std::vector<std::string>& args,
                      std::vector<std::string>* out);

// The names (underscored) of all flags of `cmd`: its own, the shared ones it lists, --verbose.
std::vector<std::string> CommandFlagNames(const Command& cmd);

// Exit codes, the same for every command (listed by `carmba help`):
//   0  success;
//   1  the data: an input file that cannot be read or is wrong, a solve that fails, an existing
//      result in --out, a file system that refuses the output;
//   2  the command line itself (seen without reading any input): an unknown command or flag, a
//      flag of another command, a flag value that does not parse or is outside its plausible
//      range, a required flag left out, a stray argument, an --out that is one of the inputs.
inline constexpr int kExitData = 1;
inline constexpr int kExitUsage = 2;

// Prints "carmba <command>: error: <message>" as one line on stderr and returns kExitData.
int Fail(const std::string& command, const Status& status);
int Fail(const std::string& command, const std::string& message);
// The same for a usage error: returns kExitUsage.
int FailUsage(const std::string& command, const Status& status);
int FailUsage(const std::string& command, const std::string& message);

}  // namespace carmba::cli

#define CARMBA_REGISTER_COMMAND(name, summary, fn)                     \
  static const bool carmba_registered_##name [[maybe_unused]] =        \
      ::carmba::cli::RegisterCommand(#name, summary, __FILE__, fn)

#define CARMBA_COMMAND_FLAGS(name, shared_flags_csv)                  \
  static const bool carmba_flags_##name [[maybe_unused]] =            \
      ::carmba::cli::RegisterCommandFlags(#name, shared_flags_csv)

#define CARMBA_REQUIRED_FLAGS(name, required_flags_csv)               \
  static const bool carmba_required_##name [[maybe_unused]] =         \
      ::carmba::cli::RegisterRequiredFlags(#name, required_flags_csv)
