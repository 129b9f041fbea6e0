// The `carmba` command's subcommand registry.
//
// Each subcommand lives in its own file src/cli/cmd_<name>.cc, defines its gflags there, and
// registers itself:
//
//   DEFINE_string(problem, "", "Problem YAML file (what is estimated from which data).");
//   static int RunSolve() { ... return 0; }
//   CARMBA_REGISTER_COMMAND(solve, "Solve a pose problem ...", RunSolve);
//
// `carmba <cmd> --help` lists exactly the flags defined in that command's file. A flag that
// belongs to another subcommand is rejected. Library code never reads FLAGS_*.
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

// Prints "carmba <command>: error: <message>" as one line on stderr and returns exit code 1.
int Fail(const std::string& command, const Status& status);
int Fail(const std::string& command, const std::string& message);

}  // namespace carmba::cli

#define CARMBA_REGISTER_COMMAND(name, summary, fn)                     \
  static const bool carmba_registered_##name [[maybe_unused]] =        \
      ::carmba::cli::RegisterCommand(#name, summary, __FILE__, fn)
