// SHA-256 of input files against the FIPS 180-2 test vectors (what `sha256sum` prints).
#include "core/file_digest.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "core/error.h"

using namespace mbsdf;

TEST(FileDigest, Sha256OfKnownContents) {
  const auto dir = std::filesystem::temp_directory_path() / "microbsdf_tests";
  std::filesystem::create_directories(dir);
  const std::string abc = (dir / "abc.txt").string(), empty = (dir / "empty.txt").string();
  std::ofstream(abc) << "abc";
  std::ofstream(empty).close();
  EXPECT_EQ(sha256OfFile(abc), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(sha256OfFile(empty), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  try {
    sha256OfFile((dir / "missing.txt").string());
    FAIL() << "no error for a missing file";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("missing.txt"), std::string::npos) << e.what();
  }
}
