// Reading carmba's markdown documentation (src/docs/*.md) for the tests that keep it true:
// fenced blocks with their info string, and the key tables marked `<!-- keys: KIND -->`.
//
// A fenced block's info string is `LANG [KIND] [file=NAME]`, e.g. ```yaml pose-problem
// file=pose_problem.yaml```. A key table is the first markdown table after its marker; each row's
// first cell holds the key in backticks.
#pragma once

#include <fstream>
#include <nlohmann/json.hpp>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace carmba::test {

struct DocBlock {
  std::string lang, kind, file, text;
  int line = 0;      // of the opening fence, 1-based
  int end_line = 0;  // of the closing fence
};

struct MarkdownDoc {
  std::vector<DocBlock> blocks;
  std::map<std::string, std::vector<std::string>> tables;  // kind -> keys in order
  std::map<std::string, int> table_lines;                  // kind -> line of the marker
};

inline MarkdownDoc ReadMarkdownDoc(const std::string& path) {
  MarkdownDoc doc;
  std::ifstream in(path);
  std::string line;
  int n = 0;
  DocBlock* open = nullptr;
  std::string table_kind;
  bool in_table = false;
  while (std::getline(in, line)) {
    ++n;
    if (open) {
      if (line.rfind("```", 0) == 0) {
        open->end_line = n;
        open = nullptr;
      } else {
        open->text += line + "\n";
      }
      continue;
    }
    if (line.rfind("```", 0) == 0) {
      DocBlock b;
      b.line = n;
      std::istringstream info(line.substr(3));
      std::string word;
      info >> b.lang;
      while (info >> word) {
        if (word.rfind("file=", 0) == 0) {
          b.file = word.substr(5);
        } else {
          b.kind = word;
        }
      }
      doc.blocks.push_back(b);
      open = &doc.blocks.back();
      continue;
    }
    const std::string marker = "<!-- keys: ";
    if (line.rfind(marker, 0) == 0) {
      table_kind = line.substr(marker.size(), line.find(" -->") - marker.size());
      doc.tables[table_kind];
      doc.table_lines[table_kind] = n;
      in_table = false;
      continue;
    }
    if (!table_kind.empty()) {
      if (line.rfind("|", 0) == 0) {
        if (!in_table) {  // the header row; the separator row follows
          in_table = true;
          std::getline(in, line);
          ++n;
          continue;
        }
        const auto a = line.find('`'), b = line.find('`', a + 1);
        const auto cell_end = line.find('|', 1);
        if (a != std::string::npos && b != std::string::npos && b < cell_end) {
          doc.tables[table_kind].push_back(line.substr(a + 1, b - a - 1));
        } else {
          doc.tables[table_kind].push_back("(row without a `key`: " + line + ")");
        }
      } else if (in_table) {
        table_kind.clear();
        in_table = false;
      }
    }
  }
  return doc;
}

// The elements of `a` that are not in `b`.
inline std::set<std::string> Minus(const std::set<std::string>& a, const std::set<std::string>& b) {
  std::set<std::string> out;
  for (const auto& x : a) {
    if (!b.count(x)) out.insert(x);
  }
  return out;
}

// "a, b, c" of a set, for messages.
inline std::string JoinSet(const std::set<std::string>& s) {
  std::string out;
  for (const auto& x : s) out += (out.empty() ? "" : ", ") + x;
  return out.empty() ? "(none)" : out;
}

// Dotted key paths of `j` up to `depth` components, lists of objects written `[]` (their
// elements' keys united), as formats.md's output tables list them.
inline void FlattenJsonKeys(const nlohmann::json& j, const std::string& prefix, int depth,
             std::set<std::string>* out) {
  if (depth == 0) return;
  if (j.is_array()) {
    for (const auto& e : j) {
      if (e.is_object()) FlattenJsonKeys(e, prefix + "[]", depth, out);
    }
    return;
  }
  if (!j.is_object()) return;
  for (const auto& [k, v] : j.items()) {
    const std::string key = prefix.empty() ? k : prefix + "." + k;
    out->insert(key);
    FlattenJsonKeys(v, key, depth - 1, out);
  }
}

}  // namespace carmba::test
