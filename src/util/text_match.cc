#include "util/text_match.h"

#include <algorithm>

namespace carmba {

int EditDistance(const std::string& a, const std::string& b) {
  // One row of the dynamic-programming table: row[j] = distance(a[0..i), b[0..j)).
  std::vector<int> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = static_cast<int>(j);
  for (size_t i = 1; i <= a.size(); ++i) {
    int diagonal = row[0];
    row[0] = static_cast<int>(i);
    for (size_t j = 1; j <= b.size(); ++j) {
      const int up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = up;
    }
  }
  return row[b.size()];
}

std::string ClosestMatch(const std::string& name, const std::vector<std::string>& candidates) {
  const int max_edits = std::max<int>(2, static_cast<int>(name.size()) / 3);
  std::string best;
  int best_d = max_edits + 1;
  for (const auto& c : candidates) {
    int d = EditDistance(name, c);
    // One is the start of the other ("--output" for "--out"): a plausible misspelling whatever
    // the length, ranked as the most distant that is still accepted.
    const bool prefix = name.size() > 3 && c.size() > 3 &&
                        (name.compare(0, c.size(), c) == 0 || c.compare(0, name.size(), name) == 0);
    if (prefix) d = std::min(d, max_edits);
    if (d < best_d) {
      best_d = d;
      best = c;
    }
  }
  return best;
}

}  // namespace carmba
