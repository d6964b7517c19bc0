// Lists of names in text files ("joints WRJ1 WRJ0 ..."): split a line's words, and write them
// back each after a space, so `key + joinWords(names)` is a header line.
#pragma once
#include <sstream>
#include <string>
#include <vector>

namespace adroit {

inline std::vector<std::string> splitWords(const std::string& text) {
  std::istringstream in(text);
  std::vector<std::string> words;
  for (std::string word; in >> word;) words.push_back(word);
  return words;
}

inline std::string joinWords(const std::vector<std::string>& words) {
  std::string text;
  for (const auto& word : words) text += " " + word;
  return text;
}

}  // namespace adroit
