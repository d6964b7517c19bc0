#include "adroit_core/bounded_file.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

namespace {

using adroit::FileError;
using adroit::readBoundedFile;

std::string errorOf(const std::string& path, size_t limit) {
  try {
    readBoundedFile(path, limit);
  } catch (const FileError& e) {
    return e.what();
  }
  return "";
}

class BoundedFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() / ("adroit_bounded_" + std::to_string(getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path) << text;
    return path;
  }
  std::filesystem::path dir_;
};

TEST_F(BoundedFile, ReadsARegularFileWithinItsLimit) {
  EXPECT_EQ(readBoundedFile(write("a.txt", "hello\n"), 6), "hello\n");
  EXPECT_EQ(readBoundedFile(write("empty", ""), 6), "");
}

TEST_F(BoundedFile, RefusesAFileOverItsLimitNamingFileAndLimit) {
  const std::string path = write("big", std::string(2048, 'x'));
  EXPECT_EQ(errorOf(path, 1024), path + ": 2 kB, over the limit of 1 kB");
  // One byte over: the sizes round alike, so the bytes are given.
  EXPECT_EQ(errorOf(path, 2047), path + ": 2 kB (2048 bytes), over the limit of 2 kB (2047 bytes)");
}

TEST_F(BoundedFile, RefusesAFifoWithoutBlocking) {
  const std::string path = (dir_ / "fifo").string();
  ASSERT_EQ(mkfifo(path.c_str(), 0600), 0);
  EXPECT_EQ(errorOf(path, 1024), path + ": not a regular file (a FIFO)");
}

TEST_F(BoundedFile, RefusesDevicesAndDirectories) {
  EXPECT_EQ(errorOf("/dev/zero", 1024), "/dev/zero: not a regular file (a character device)");
  EXPECT_EQ(errorOf(dir_.string(), 1024), dir_.string() + ": not a regular file (a directory)");
}

TEST_F(BoundedFile, NamesAMissingFile) {
  const std::string path = (dir_ / "missing").string();
  EXPECT_EQ(errorOf(path, 1024), path + ": cannot open (No such file or directory)");
  EXPECT_EQ(errorOf("", 1024), "no file named (empty path)");
}

TEST_F(BoundedFile, RequireRegularFileGivesTheSizeOrTheSameErrors) {
  EXPECT_EQ(adroit::requireRegularFile(write("a.bag", "12345"), 5), 5u);
  EXPECT_THROW(adroit::requireRegularFile(write("b.bag", "123456"), 5), FileError);
  EXPECT_THROW(adroit::requireRegularFile("/dev/zero", 5), FileError);
  EXPECT_THROW(adroit::requireRegularFile(dir_.string(), 5), FileError);
}

TEST(DescribeBytes, ReadsAsAPersonWouldSayIt) {
  EXPECT_EQ(adroit::describeBytes(12), "12 B");
  EXPECT_EQ(adroit::describeBytes(64 * adroit::kMiB), "64 MB");
  EXPECT_EQ(adroit::describeBytes(3 * adroit::kGiB + adroit::kGiB / 2), "3.5 GB");
}

}  // namespace
