// A fresh directory under /tmp, removed with everything in it when the object goes; and one
// such directory per test process (scratchDir) for tests that only need somewhere to write.
#pragma once

#include <stdlib.h>

#include <filesystem>
#include <string>

namespace adroit::teleop::test {

class TempDir {
 public:
  TempDir() {
    char tmpl[] = "/tmp/adroit_teleop_test_XXXXXX";
    if (mkdtemp(tmpl)) path_ = tmpl;
  }
  ~TempDir() {
    if (!path_.empty()) std::filesystem::remove_all(path_);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

inline const std::string& scratchDir() {
  static const TempDir dir;
  return dir.path();
}

}  // namespace adroit::teleop::test
