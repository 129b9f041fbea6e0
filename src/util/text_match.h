// Closest-name suggestions for misspelt names (command-line flags, commands).
#pragma once

#include <string>
#include <vector>

namespace carmba {

// Levenshtein distance (insertions, deletions, substitutions, each of cost 1).
int EditDistance(const std::string& a, const std::string& b);

// The candidate closest to `name` by EditDistance, or "" when none is close enough to be a
// plausible misspelling: at most max(2, |name| / 3) edits away, or one is the start of the other
// (both longer than 3 characters). Ties go to the first candidate.
std::string ClosestMatch(const std::string& name, const std::vector<std::string>& candidates);

}  // namespace carmba
