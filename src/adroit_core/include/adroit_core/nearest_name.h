// The known name closest to a misspelt one, for error messages that say what was meant:
// "unknown parameter watchdog_timout (did you mean watchdog_timeout?)".
#pragma once

#include <string>
#include <vector>

namespace adroit {

// Edit distance (insertions, deletions, substitutions and swaps of neighbours count 1).
size_t editDistance(const std::string& a, const std::string& b);

// The candidate nearest to `name`, or "" when none is within a third of its length (at least
// 2 edits), so a guess is offered only when it is plausibly the one meant.
std::string nearestName(const std::string& name, const std::vector<std::string>& candidates);

// " (did you mean X?)" or "" when no candidate is near: the tail of an error line.
std::string didYouMean(const std::string& name, const std::vector<std::string>& candidates);

}  // namespace adroit
