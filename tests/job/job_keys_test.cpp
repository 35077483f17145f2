// The registry of job keys against the parser and the job reference: the parser reads registered keys
// only (every job of jobs/ and of the fuzz corpus loads without a registry error), the reference's
// generated table is the registry's, every registered key is described in the reference's prose and
// every key the prose describes is registered, and an unknown key is answered with the nearest one.
#include "job/job_keys.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>

#include "core/error.h"
#include "job/job.h"

using namespace mbsdf;

namespace {

std::string readFile(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string reference() {
  return readFile(std::string(MICROBSDF_SOURCE_DIR) + "/docs/job-reference.md");
}

constexpr const char* kGeneratedHeading = "## Every key at a glance";

}  // namespace

TEST(JobKeys, PathsAreUniqueAndSectionsRegistered) {
  std::set<std::string> seen;
  for (const JobKey& k : jobKeys()) {
    EXPECT_TRUE(seen.insert(std::string(k.path)).second) << k.path;
    const size_t dot = k.path.rfind('.');
    if (dot != std::string_view::npos) {
      EXPECT_NE(findJobKey(k.path.substr(0, dot)), nullptr) << k.path;
    }
    EXPECT_FALSE(k.meaning.empty()) << k.path;
  }
}

// Every job the project ships and every fuzz input: the parser never reads an unregistered key (that
// would be a std::logic_error, not an InputError).
TEST(JobKeys, TheParserReadsOnlyRegisteredKeys) {
  const std::string root = MICROBSDF_SOURCE_DIR;
  int loaded = 0;
  for (const char* dir : {"/jobs", "/tests/fuzz/corpus/job", "/tests/fuzz/regressions/job"}) {
    for (const auto& e : std::filesystem::recursive_directory_iterator(root + dir)) {
      if (!e.is_regular_file()) continue;
      if (std::string(dir) == "/jobs" && e.path().extension() != ".toml") continue;
      try {
        if (std::string(dir) == "/jobs")
          loadJob(e.path().string());
        else
          loadJobFromString(readFile(e.path()), "fuzz.toml", "/nonexistent");
        ++loaded;
      } catch (const InputError&) {
      }
    }
  }
  EXPECT_GT(loaded, 10);
}

TEST(JobKeys, TheReferenceEndsWithTheRegistry) {
  const std::string doc = reference();
  const size_t at = doc.find(kGeneratedHeading);
  ASSERT_NE(at, std::string::npos) << "docs/job-reference.md lacks \"" << kGeneratedHeading << "\"";
  const size_t table = doc.find("| key |", at);
  ASSERT_NE(table, std::string::npos);
  EXPECT_EQ(doc.substr(table), jobKeysMarkdown())
      << "docs/job-reference.md's last table differs from the registry: regenerate it with `microbsdf keys --markdown`";
}

TEST(JobKeys, TheReferenceDescribesEveryRegisteredKey) {
  const std::string doc = reference();
  const std::string prose = doc.substr(0, doc.find(kGeneratedHeading));
  for (const JobKey& k : jobKeys()) {
    if (k.type == KeyType::Table) continue;
    const std::string path(k.path);
    const std::string name = path.substr(path.rfind('.') + 1);
    const std::string inSection = path.substr(path.find('.') + 1);  // `defects.texel_um` under [geometry]
    const bool described =
        prose.find("`" + path + "`") != std::string::npos || prose.find("`" + name + "`") != std::string::npos ||
        prose.find("`" + inSection + "`") != std::string::npos || prose.find("`" + name + " ") != std::string::npos ||
        prose.find("{ " + name + " = ") != std::string::npos || prose.find(", " + name + " = ") != std::string::npos;
    EXPECT_TRUE(described) << path << " is registered but the job reference does not describe it";
  }
  // And the other way: every key the reference's tables describe is registered. The first cell of
  // a row names keys (in their section's table, or as section.key); the kind table lists them with
  // their defaults.
  std::istringstream lines(prose);
  std::string line, section;
  const std::regex heading(R"(^### `\[([a-z]+)\]`)"), keyCell(R"(`([a-z_]+(\.[a-z_]+)?)`)");
  int checked = 0;
  while (std::getline(lines, line)) {
    std::smatch m;
    if (std::regex_search(line, m, heading)) section = m[1];
    if (line.rfind("| `", 0) != 0) continue;
    const std::string first = line.substr(0, line.find(" |", 2));
    for (auto it = std::sregex_iterator(first.begin(), first.end(), keyCell); it != std::sregex_iterator(); ++it) {
      const std::string key = (*it)[1];
      if (section == "geometry" && findJobKey("geometry.kind") && key.find('_') == std::string::npos &&
          findJobKey("geometry." + key) == nullptr)
        continue;  // a geometry kind's name in the kind table, not a key
      // A dotted cell is a full path or, like `defects.texel_um` under [geometry], a sub-table's key.
      const std::string path =
          key.find('.') == std::string::npos || findJobKey(section + "." + key) ? section + "." + key : key;
      EXPECT_NE(findJobKey(path), nullptr) << path << " is described in the job reference but not registered";
      ++checked;
    }
  }
  EXPECT_GT(checked, 40);
}

TEST(JobKeys, AnUnknownKeyIsAnsweredWithTheNearestOne) {
  try {
    loadJobFromString("[sampling]\npath_per_slice = 1000\n", "typo.toml", "");
    FAIL() << "an unknown key was accepted";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("typo.toml:2"), std::string::npos) << what;
    EXPECT_NE(what.find("did you mean 'sampling.paths_per_slice'"), std::string::npos) << what;
  }
  EXPECT_EQ(nearestJobKey("scene.tolerence"), "scene.tolerance");
  EXPECT_EQ(nearestJobKey("scene.completely_different"), "");
}
