// The keys of a job file, in one registry: section and name, type, default, range and meaning.
// The parser's dictionary (params.h) refuses to read a key the registry does not hold, an unknown
// key in a job file is reported with the registry's nearest name, and `microbsdf keys` prints the
// registry as the table docs/job-reference.md ends with (tests/job/job_keys_test.cpp fails when the
// reference and the registry disagree).
#pragma once
#include <string>
#include <string_view>
#include <vector>

namespace mbsdf {

// What a key's value may be in TOML. A Number key also takes an integer; a Numbers key one number
// or an array of them; a Strings key one string or an array of them.
enum class KeyType { Table, String, Strings, Number, Numbers, Integer, Boolean, StringOrNumbers, NumbersOrTable };

struct JobKey {
  std::string_view path;  // "section.name" ("spectrum.wavelengths_nm.min" inside a sub-table)
  KeyType type;
  std::string_view defaultText;  // as the reference shows it ("—": none, the key is optional)
  std::string_view range;        // accepted values ("> 0", a closed set), "" when any of the type
  std::string_view meaning;      // one line
};

const std::vector<JobKey>& jobKeys();
// The registry's entry for a path, or nullptr.
const JobKey* findJobKey(std::string_view path);
// The registered path nearest to `path` (edit distance within its section), or "" when none is close.
std::string nearestJobKey(std::string_view path);
std::string_view keyTypeName(KeyType t);
// The registry as a Markdown table (`microbsdf keys --markdown`) or as aligned text.
std::string jobKeysMarkdown();
std::string jobKeysText();

}  // namespace mbsdf
