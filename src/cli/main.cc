// carmba: C-arm calibration and pose estimation. Dispatches to subcommands (cli/command.h).
#include <gflags/gflags.h>
#include <glog/logging.h>

#include <algorithm>
#include <cstring>
#include <iostream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "cli/command.h"

DEFINE_bool(verbose, false, "Log progress (glog INFO) to stderr.");

namespace carmba::cli {
namespace {

std::vector<Command>& Registry() {
  static std::vector<Command> r;
  return r;
}

std::map<std::string, std::vector<std::string>>& SharedFlags() {
  static std::map<std::string, std::vector<std::string>> r;
  return r;
}

bool IsSharedFlagFile(const std::string& filename) {
  return filename.find("common_flags.cc") != std::string::npos;
}

std::string BaseName(const std::string& p) {
  const auto pos = p.find_last_of('/');
  return pos == std::string::npos ? p : p.substr(pos + 1);
}

void PrintUsage() {
  std::cout << "carmba: C-arm X-ray calibration and pose estimation as one bundle adjustment.\n\n"
               "Usage: carmba <command> [--flag=value ...]\n"
               "       carmba <command> --help   (the command's flags)\n\nCommands:\n";
  std::vector<Command> cmds = Registry();
  std::sort(cmds.begin(), cmds.end(),
            [](const Command& a, const Command& b) { return a.name < b.name; });
  for (const auto& c : cmds) {
    std::cout << "  " << c.name << std::string(std::max<size_t>(2, 16 - c.name.size()), ' ')
              << c.summary << "\n";
  }
  std::cout << "  help            This list.\n";
}

void PrintCommandHelp(const Command& cmd) {
  std::cout << "carmba " << cmd.name << ": " << cmd.summary << "\n\nFlags:\n";
  std::vector<gflags::CommandLineFlagInfo> flags;
  gflags::GetAllFlags(&flags);
  for (const auto& f : flags) {
    const auto shared = CommandSharedFlags(cmd.name);
    const bool listed = IsSharedFlagFile(f.filename) &&
                        std::find(shared.begin(), shared.end(), f.name) != shared.end();
    if (BaseName(f.filename) != BaseName(cmd.file) && f.name != "verbose" && !listed) continue;
    std::cout << "  --" << f.name << " (" << f.type << ", default '" << f.default_value
              << "')\n      " << f.description << "\n";
  }
}

}  // namespace

bool RegisterCommand(const char* name, const char* summary, const char* file, int (*run)()) {
  Registry().push_back(Command{name, summary, file, run});
  return true;
}

const std::vector<Command>& Commands() { return Registry(); }

bool RegisterCommandFlags(const char* name, const char* shared_flags_csv) {
  std::vector<std::string>& v = SharedFlags()[name];
  std::string s = shared_flags_csv, item;
  for (char ch : s + ",") {
    if (ch == ',') {
      if (!item.empty()) v.push_back(item);
      item.clear();
    } else if (ch != ' ') {
      item += ch;
    }
  }
  return true;
}

std::vector<std::string> CommandSharedFlags(const std::string& name) {
  auto it = SharedFlags().find(name);
  return it == SharedFlags().end() ? std::vector<std::string>() : it->second;
}

int Fail(const std::string& command, const std::string& message) {
  std::cerr << "carmba " << command << ": error: " << message << std::endl;
  return 1;
}

int Fail(const std::string& command, const Status& status) {
  return Fail(command, status.message());
}

}  // namespace carmba::cli

int main(int argc, char** argv) {
  using carmba::cli::Command;
  if (argc < 2 || !std::strcmp(argv[1], "help") || !std::strcmp(argv[1], "--help") ||
      !std::strcmp(argv[1], "-h")) {
    carmba::cli::PrintUsage();
    return argc < 2 ? 2 : 0;
  }
  const std::string name = argv[1];
  const Command* cmd = nullptr;
  for (const auto& c : carmba::cli::Commands()) {
    if (c.name == name) cmd = &c;
  }
  if (!cmd) {
    std::cerr << "carmba: error: unknown command '" << name << "' (see 'carmba help')"
              << std::endl;
    return 2;
  }
  // Drop the command name and parse the rest as this command's flags. Dashes inside a flag's
  // name are read as underscores (--spacing-mm = --spacing_mm), as users type them.
  std::vector<std::string> normalized;
  for (int i = 2; i < argc; ++i) {
    std::string a = argv[i];
    if (a.size() > 2 && a[0] == '-') {
      const size_t start = a[1] == '-' ? 2 : 1;
      const size_t end = std::min(a.find('='), a.size());
      for (size_t k = start; k < end; ++k) {
        if (a[k] == '-') a[k] = '_';
      }
    }
    normalized.push_back(a);
  }
  std::vector<char*> args;
  args.push_back(argv[0]);
  for (int i = 2; i < argc; ++i) {
    argv[i] = normalized[i - 2].data();
    if (!std::strcmp(argv[i], "--help") || !std::strcmp(argv[i], "-h") ||
        !std::strcmp(argv[i], "-help")) {
      carmba::cli::PrintCommandHelp(*cmd);
      return 0;
    }
    args.push_back(argv[i]);
  }
  int nargs = static_cast<int>(args.size());
  char** pargs = args.data();
  gflags::SetUsageMessage("carmba " + name + " (see 'carmba " + name + " --help')");
  gflags::ParseCommandLineFlags(&nargs, &pargs, /*remove_flags=*/true);
  if (nargs > 1) {
    return carmba::cli::Fail(name, std::string("unexpected argument '") + pargs[1] +
                                       "' (flags are written --name=value)");
  }
  // Reject flags that belong to other subcommands.
  std::vector<gflags::CommandLineFlagInfo> flags;
  gflags::GetAllFlags(&flags);
  for (const auto& f : flags) {
    if (f.is_default || f.name == "verbose") continue;
    const bool other_cmd = f.filename.find("/cli/cmd_") != std::string::npos &&
                           carmba::cli::BaseName(f.filename) != carmba::cli::BaseName(cmd->file);
    const auto shared = carmba::cli::CommandSharedFlags(name);
    const bool unlisted_shared =
        carmba::cli::IsSharedFlagFile(f.filename) &&
        std::find(shared.begin(), shared.end(), f.name) == shared.end();
    if (other_cmd || unlisted_shared) {
      return carmba::cli::Fail(name, "flag --" + f.name + " is not a flag of '" + name +
                                         "' (see 'carmba " + name + " --help')");
    }
  }
  FLAGS_logtostderr = true;
  FLAGS_minloglevel = FLAGS_verbose ? 0 : 1;
  google::InitGoogleLogging(argv[0]);
  return cmd->run();
}
