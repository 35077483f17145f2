// The output location: folders refused, one lock holder at a time, the lock's record.
#include "io/output_target.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <optional>

#include "core/error.h"

using namespace mbsdf;

namespace {
std::string scratch(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / "microbsdf_tests" / "output_target";
  std::filesystem::create_directories(dir);
  return (dir / name).string();
}
}  // namespace

TEST(OutputTarget, FolderAsOutputIsAnInputError) {
  const std::string dir = scratch("a-folder");
  std::filesystem::create_directories(dir);
  try {
    checkOutputPath(dir);
    FAIL() << "a folder was accepted as the output";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("is a folder"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(checkOutputPath(scratch("new/sub/out.h5")));  // folders are created
  EXPECT_TRUE(std::filesystem::is_directory(scratch("new/sub")));
  EXPECT_GT(freeBytesAt(scratch("new/sub/out.h5")), 0);
}

TEST(OutputTarget, OneLockHolderAndItsRecord) {
  const std::string out = scratch("locked.h5");
  std::filesystem::remove(out + ".lock");
  std::optional<OutputLock> first(std::in_place, out);
  EXPECT_TRUE(first->previousHolder().empty());
  // flock locks belong to the open file description: a second open in this process conflicts
  // exactly as another process's would.
  try {
    OutputLock second(out);
    FAIL() << "a second lock on the same output was granted";
  } catch (const OutputBusyError& e) {
    EXPECT_NE(std::string(e.what()).find("PID"), std::string::npos) << e.what();
  }
  first.reset();
  EXPECT_FALSE(std::filesystem::exists(out + ".lock"));  // released: removed
  // A record left by a process that is gone (its flock died with it) is taken over and reported.
  std::ofstream(out + ".lock") << "host elsewhere, PID 1, since yesterday\n";
  OutputLock third(out);
  EXPECT_EQ(third.previousHolder(), "host elsewhere, PID 1, since yesterday");
}

// What another rank sees of a held lock: held where the file system carries the lock, missing or
// foreign where its folder is another file system, unenforced where flock(2) grants it anyway. A
// lock file with the record but nobody holding it is what a rank on a node the lock does not
// reach sees.
TEST(OutputTarget, ViewsOfTheLockFromAnotherRank) {
  const std::string out = scratch("viewed.h5");
  std::filesystem::remove(out + ".lock");
  EXPECT_EQ(viewOfLock(out + ".lock", "anything"), LockView::Missing);
  std::string record;
  {
    OutputLock lock(out);
    record = lock.record();
    EXPECT_NE(record.find("PID"), std::string::npos) << record;
    EXPECT_EQ(viewOfLock(lock.path(), record), LockView::Held);
    EXPECT_EQ(viewOfLock(lock.path(), "host elsewhere, PID 1, since yesterday"), LockView::Foreign);
    // Looking left the holder's lock as it was.
    EXPECT_THROW(OutputLock second(out), OutputBusyError);
  }
  std::ofstream(out + ".lock") << record << "\n";
  EXPECT_EQ(viewOfLock(out + ".lock", record), LockView::Unenforced);
  OutputLock again(out);  // the unenforced view let go of the lock it took
  EXPECT_EQ(viewOfLock(again.path(), again.record()), LockView::Held);
}
