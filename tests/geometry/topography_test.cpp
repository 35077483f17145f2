// Measured-topography readers: inputs found by fuzz_topography (scripts/fuzz) end in an
// InputError naming the file, or in a consistent read.
#include "geometry/topography.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "core/error.h"

namespace mbsdf {
namespace {

TEST(TopographyReaders, FuzzRegressions) {
  const std::string dir = std::string(MICROBSDF_SOURCE_DIR) + "/tests/fuzz/regressions/topography";
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    std::ifstream in(entry.path(), std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_FALSE(bytes.empty());
    // As in fuzz_topography: the first byte picks the format, the rest is the file.
    static const char* kExtensions[] = {".x3p", ".sdf", ".gsf"};
    const std::string path = (std::filesystem::temp_directory_path() /
                              ("mbsdf-topography-regression" + std::string(kExtensions[uint8_t(bytes[0]) % 3])))
                                 .string();
    std::ofstream(path, std::ios::binary) << bytes.substr(1);
    try {
      const Topography t = loadTopography(path);
      EXPECT_EQ(t.z_um.size(), t.size()) << entry.path();
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("mbsdf-topography-regression"), std::string::npos) << e.what();
    }
    std::filesystem::remove(path);
    ++files;
  }
  EXPECT_GT(files, 0);
}

}  // namespace
}  // namespace mbsdf
