// carmba: C-arm calibration and pose estimation. Dispatches to subcommands (cli/command.h).
//
// The command line is the same for every subcommand:
//   carmba --version | carmba version
//   carmba help | carmba help <command> | carmba <command> --help
//   carmba <command> --flag-name=value --flag-name value --bool-flag --no-bool-flag
// Flag names are written with dashes (as in --help and the README) or underscores: both work.
// A flag the command does not have is a one-line error suggesting the closest of its flags;
// a required flag that is missing is a one-line error too, before any work.
#include <gflags/gflags.h>
#include <glog/logging.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "cli/command.h"
#include "cli/common_flags.h"
#include "util/allocator.h"
#include "util/file_util.h"
#include "util/temp_paths.h"
#include "util/text_match.h"

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

std::map<std::string, std::vector<std::string>>& RequiredFlags() {
  static std::map<std::string, std::vector<std::string>> r;
  return r;
}

std::vector<std::string> SplitCsv(const std::string& csv) {
  std::vector<std::string> v;
  std::string item;
  for (char ch : csv + ",") {
    if (ch == ',') {
      if (!item.empty()) v.push_back(item);
      item.clear();
    } else if (ch != ' ') {
      item += ch;
    }
  }
  return v;
}

bool Contains(const std::vector<std::string>& v, const std::string& s) {
  return std::find(v.begin(), v.end(), s) != v.end();
}

bool IsSharedFlagFile(const std::string& filename) {
  return BaseName(filename) == "common_flags.cc";
}

// The flags of `cmd`: those DEFINEd in its file, the shared ones it lists, and --verbose.
std::vector<gflags::CommandLineFlagInfo> CommandFlags(const Command& cmd) {
  std::vector<gflags::CommandLineFlagInfo> all, mine;
  gflags::GetAllFlags(&all);  // sorted by name
  const auto shared = CommandSharedFlags(cmd.name);
  for (const auto& f : all) {
    const bool own = BaseName(f.filename) == BaseName(cmd.file);
    const bool listed = IsSharedFlagFile(f.filename) && (Contains(shared, f.name) ||
                                                         f.name == "verbose");
    if (own || listed) mine.push_back(f);
  }
  return mine;
}

std::string Dashed(std::string name) {
  std::replace(name.begin(), name.end(), '_', '-');
  return name;
}

std::string Underscored(std::string name) {
  std::replace(name.begin(), name.end(), '-', '_');
  return name;
}

// `text` in lines of at most `width` characters (words are not split), each after `indent`.
std::string Wrapped(const std::string& text, const std::string& indent, size_t width) {
  std::string out, line, word;
  auto flush_word = [&]() {
    if (word.empty()) return;
    if (!line.empty() && indent.size() + line.size() + 1 + word.size() > width) {
      out += indent + line + "\n";
      line.clear();
    }
    line += (line.empty() ? "" : " ") + word;
    word.clear();
  };
  for (char c : text) {
    if (c == ' ' || c == '\n') {
      flush_word();
    } else {
      word += c;
    }
  }
  flush_word();
  if (!line.empty()) out += indent + line + "\n";
  return out;
}

const Command* FindCommand(const std::string& name) {
  for (const auto& c : Registry()) {
    if (c.name == name) return &c;
  }
  return nullptr;
}

std::vector<Command> SortedCommands() {
  std::vector<Command> cmds = Registry();
  std::sort(cmds.begin(), cmds.end(),
            [](const Command& a, const Command& b) { return a.name < b.name; });
  return cmds;
}

// "" when `value` parses as a value of `type` (gflags' types), else what was expected: gflags
// would print its own message and exit 1 on it.
std::string ExpectedFlagValue(const std::string& type, const std::string& value) {
  const char* begin = value.c_str();
  char* end = nullptr;
  errno = 0;
  if (type == "bool") {
    std::string v = value;
    std::transform(v.begin(), v.end(), v.begin(), [](unsigned char c) { return std::tolower(c); });
    for (const char* ok : {"true", "false", "1", "0", "yes", "no", "t", "f", "y", "n"}) {
      if (v == ok) return "";
    }
    return "true or false";
  }
  if (type == "int32" || type == "int64") {
    const long long v = std::strtoll(begin, &end, 10);
    const bool fits = type == "int64" || (v >= INT32_MIN && v <= INT32_MAX);
    return !value.empty() && *end == '\0' && errno == 0 && fits ? "" : "an integer";
  }
  if (type == "uint32" || type == "uint64") {
    std::strtoull(begin, &end, 10);
    const bool ok = !value.empty() && value[0] != '-' && *end == '\0' && errno == 0;
    return ok ? "" : "a non-negative integer";
  }
  if (type == "double") {
    const double v = std::strtod(begin, &end);
    return !value.empty() && *end == '\0' && std::isfinite(v) ? "" : "a number";
  }
  return "";
}

}  // namespace

std::string UsageText() {
  std::string s =
      "carmba: C-arm X-ray calibration and pose estimation as one bundle adjustment.\n\n"
      "Usage: carmba <command> [--flag-name=value ...]\n"
      "       carmba help <command>   (or carmba <command> --help: the command's flags)\n"
      "       carmba --version\n\nCommands:\n";
  for (const auto& c : SortedCommands()) {
    s += "  " + c.name + std::string(std::max<size_t>(2, 16 - c.name.size()), ' ') + c.summary +
         "\n";
  }
  s += "  help            This list, or a command's flags (carmba help <command>).\n";
  s += "\nExit codes (every command):\n"
       "  0  success\n"
       "  1  the data: an input that cannot be read or is wrong, a solve that fails, an existing\n"
       "     result in --out (without --force), a file system that refuses the output\n"
       "  2  usage: an unknown command or flag, a flag value that does not parse or is outside\n"
       "     its plausible range, a required flag left out, a stray argument, an --out that is\n"
       "     or contains one of the command's inputs\n";
  return s;
}

std::string CommandHelpText(const Command& cmd) {
  const auto required = CommandRequiredFlags(cmd.name);
  std::string s = "carmba " + cmd.name + ": " + cmd.summary + "\n\nUsage: carmba " + cmd.name;
  for (const auto& r : required) s += " --" + Dashed(r) + "=...";
  s += " [flags]\n\nFlag names take dashes or underscores (--spacing-mm = --spacing_mm).\n";
  auto flags = CommandFlags(cmd);
  // Required flags first, in the order the command lists them; then the others by name.
  std::sort(flags.begin(), flags.end(), [&](const auto& a, const auto& b) {
    const auto ia = std::find(required.begin(), required.end(), a.name);
    const auto ib = std::find(required.begin(), required.end(), b.name);
    return ia != ib ? ia < ib : a.name < b.name;
  });
  for (const auto& f : flags) {
    const bool req = Contains(required, f.name);
    const std::string name = Dashed(f.name);
    std::string type = f.type;  // "string", "int32", "double" ... shown as STRING, INT32
    std::transform(type.begin(), type.end(), type.begin(),
                   [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
    const std::string head =
        f.type == "bool" ? "--" + name + ", --no-" + name : "--" + name + "=" + type;
    s += "\n  " + head;
    if (req) {
      s += "  (required)";
    } else if (f.type == "string" && f.default_value.empty()) {
      s += "  (default: none)";
    } else {
      s += "  (default: " + f.default_value + ")";
    }
    s += "\n" + Wrapped(f.description, "      ", 96);
  }
  return s;
}

bool RegisterCommand(const char* name, const char* summary, const char* file, int (*run)()) {
  Registry().push_back(Command{name, summary, file, run});
  return true;
}

const std::vector<Command>& Commands() { return Registry(); }

bool RegisterCommandFlags(const char* name, const char* shared_flags_csv) {
  auto& v = SharedFlags()[name];
  for (auto& f : SplitCsv(shared_flags_csv)) v.push_back(Underscored(f));
  return true;
}

bool RegisterRequiredFlags(const char* name, const char* required_flags_csv) {
  auto& v = RequiredFlags()[name];
  for (auto& f : SplitCsv(required_flags_csv)) v.push_back(Underscored(f));
  return true;
}

std::vector<std::string> CommandFlagNames(const Command& cmd) {
  std::vector<std::string> names;
  for (const auto& f : CommandFlags(cmd)) names.push_back(f.name);
  return names;
}

std::vector<std::string> CommandSharedFlags(const std::string& name) {
  auto it = SharedFlags().find(name);
  return it == SharedFlags().end() ? std::vector<std::string>() : it->second;
}

std::vector<std::string> CommandRequiredFlags(const std::string& name) {
  auto it = RequiredFlags().find(name);
  return it == RequiredFlags().end() ? std::vector<std::string>() : it->second;
}

int Fail(const std::string& command, const std::string& message) {
  std::cerr << "carmba " << command << ": error: " << message << std::endl;
  return kExitData;
}

int Fail(const std::string& command, const Status& status) {
  return Fail(command, status.message());
}

int FailUsage(const std::string& command, const std::string& message) {
  Fail(command, message);
  return kExitUsage;
}

int FailUsage(const std::string& command, const Status& status) {
  return FailUsage(command, status.message());
}

Status NormalizeFlags(const Command& cmd,
                      const std::vector<std::string>& args,
                      std::vector<std::string>* out) {
  const auto flags = CommandFlags(cmd);
  std::map<std::string, const gflags::CommandLineFlagInfo*> by_name;
  std::vector<std::string> names;
  for (const auto& f : flags) {
    by_name[f.name] = &f;
    names.push_back("--" + Dashed(f.name));
    if (f.type == "bool") names.push_back("--no-" + Dashed(f.name));
  }
  const std::string see = " (see 'carmba " + cmd.name + " --help')";
  out->clear();
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if (a == "--") {  // the rest is positional
      out->insert(out->end(), args.begin() + static_cast<long>(i), args.end());
      break;
    }
    if (a.size() < 2 || a[0] != '-' || (a[1] >= '0' && a[1] <= '9') || a[1] == '.') {
      out->push_back(a);  // a positional argument (rejected later) or a negative number
      continue;
    }
    const size_t start = a[1] == '-' ? 2 : 1;
    const size_t eq = a.find('=');
    const std::string typed = a.substr(start, eq == std::string::npos ? std::string::npos
                                                                      : eq - start);
    const std::string value = eq == std::string::npos ? "" : a.substr(eq);  // with '='
    std::string name = Underscored(typed);
    bool negated = false;
    if (!by_name.count(name) && name.size() > 2 && name.compare(0, 2, "no") == 0) {
      std::string rest = name.substr(name[2] == '_' ? 3 : 2);
      auto it = by_name.find(rest);
      if (it != by_name.end() && it->second->type == "bool") {
        name = rest;
        negated = true;
      }
    }
    auto it = by_name.find(name);
    if (it == by_name.end()) {
      gflags::CommandLineFlagInfo other;
      if (gflags::GetCommandLineFlagInfo(name.c_str(), &other)) {
        return Status::Error("flag --" + Dashed(name) + " is not a flag of '" + cmd.name + "'" +
                             see);
      }
      const std::string close = ClosestMatch("--" + Dashed(typed), names);
      return Status::Error("unknown flag --" + Dashed(typed) +
                           (close.empty() ? "" : "; did you mean " + close + "?") + see);
    }
    if (negated) {
      if (!value.empty()) {
        return Status::Error("flag --no-" + Dashed(name) + " takes no value, got '" +
                             value.substr(1) + "'");
      }
      out->push_back("--no" + name);
      continue;
    }
    const std::string& type = it->second->type;
    std::string given = value.empty() ? "" : value.substr(1);
    out->push_back("--" + name + value);
    // `--flag value`: the value is the next argument (bool flags take none).
    if (value.empty() && type != "bool") {
      if (i + 1 >= args.size()) {
        return Status::Error("flag --" + Dashed(name) + " needs a value" + see);
      }
      given = args[++i];
      out->push_back(given);
    }
    if (!value.empty() || type != "bool") {
      const std::string expected = ExpectedFlagValue(type, given);
      if (!expected.empty()) {
        return Status::Error("--" + Dashed(name) + ": expected " + expected + ", got '" + given +
                             "'" + see);
      }
    }
  }
  return Status::Ok();
}

}  // namespace carmba::cli

int main(int argc, char** argv) {
  namespace cli = carmba::cli;
  carmba::KeepFreedMemoryForReuse();
  auto is_help = [](const std::string& a) { return a == "--help" || a == "-h" || a == "-help"; };
  if (argc < 2) {
    std::cout << cli::UsageText();
    return 2;
  }
  std::string name = argv[1];
  if (name == "--version" || name == "-V") name = "version";
  if (name == "help" || is_help(name)) {
    if (argc < 3 || is_help(argv[2])) {
      std::cout << cli::UsageText();
      return 0;
    }
    name = argv[2];
    const cli::Command* cmd = cli::FindCommand(name);
    if (cmd) {
      std::cout << cli::CommandHelpText(*cmd);
      return 0;
    }
  }
  const cli::Command* cmd = cli::FindCommand(name);
  if (!cmd) {
    std::vector<std::string> names;
    for (const auto& c : cli::Commands()) names.push_back(c.name);
    const std::string close = carmba::ClosestMatch(name, names);
    std::cerr << "carmba: error: unknown command '" << name << "'"
              << (close.empty() ? "" : "; did you mean '" + close + "'?")
              << " (see 'carmba help')" << std::endl;
    return 2;
  }
  std::vector<std::string> raw(argv + 2, argv + argc);
  for (const auto& a : raw) {
    if (is_help(a)) {
      std::cout << cli::CommandHelpText(*cmd);
      return 0;
    }
  }
  std::vector<std::string> normalized;
  if (const carmba::Status s = cli::NormalizeFlags(*cmd, raw, &normalized); !s.ok()) {
    return cli::FailUsage(name, s);
  }
  std::vector<char*> args;
  args.push_back(argv[0]);
  for (auto& a : normalized) args.push_back(a.data());
  int nargs = static_cast<int>(args.size());
  char** pargs = args.data();
  gflags::SetUsageMessage("carmba " + name + " (see 'carmba " + name + " --help')");
  gflags::ParseCommandLineFlags(&nargs, &pargs, /*remove_flags=*/true);
  if (nargs > 1) {
    return cli::FailUsage(name, std::string("unexpected argument '") + pargs[1] +
                                    "' (flags are written --name=value)");
  }
  for (const auto& r : cli::CommandRequiredFlags(name)) {
    gflags::CommandLineFlagInfo f;
    if (gflags::GetCommandLineFlagInfo(r.c_str(), &f) &&
        (f.is_default || f.current_value.empty())) {
      return cli::FailUsage(name, "--" + cli::Dashed(r) + " is required (see 'carmba " + name +
                                      " --help')");
    }
  }
  if (const carmba::Status s = cli::CheckOutIsNoInput(cli::InputsOfFlagsAndFilesTheyName(
          cli::CommandFlagNames(*cmd)));
      !s.ok()) {
    return cli::FailUsage(name, s);
  }
  carmba::InstallTempPathCleanup();
  FLAGS_logtostderr = true;
  FLAGS_minloglevel = FLAGS_verbose ? 0 : 1;
  google::InitGoogleLogging(argv[0]);
  const int code = cmd->run();
  cli::EndSteps(name);
  return code;
}
