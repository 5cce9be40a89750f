// Whole files and configuration paths (util/files.hpp), shared by every parser of a file.
#include <fogbeam/util/files.hpp>

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace fogbeam {
namespace {

TEST(Files, ReadTextFileReturnsTheBytesOrSaysWhy) {
  const std::string path = (std::filesystem::temp_directory_path() / ("fogbeam-files-" + std::to_string(::getpid()))).string();
  {
    std::ofstream out(path, std::ios::binary);
    out << "line 1\r\nline 2\0tail";  // CR and the NUL that ends the literal: bytes as written
  }
  const auto text = readTextFile(path);
  ASSERT_TRUE(text) << text.error().message;
  EXPECT_EQ(*text, "line 1\r\nline 2");
  std::remove(path.c_str());
  const auto gone = readTextFile(path);
  ASSERT_FALSE(gone);
  EXPECT_EQ(gone.error().message, path + ": cannot open (No such file or directory)");
}

TEST(Files, PathsResolveAgainstTheConfigFilesFolder) {
  EXPECT_EQ(resolvePath("/cab/config", "lamps/low.ies"), "/cab/config/lamps/low.ies");
  EXPECT_EQ(resolvePath("/cab/config", "../lamps/./low.ies"), "/cab/lamps/low.ies");
  EXPECT_EQ(resolvePath("/cab/config", "/abs/low.ies"), "/abs/low.ies");
  EXPECT_EQ(resolvePath("", "lamps/low.ies"), "lamps/low.ies");
}

TEST(Files, CheckFileRefusesWhatIsNotARegularFile) {
  EXPECT_EQ(checkFile("/nonexistent/fogbeam/x.ies"), "file not found: /nonexistent/fogbeam/x.ies");
  EXPECT_EQ(checkFile("/dev/zero"), "not a regular file: /dev/zero");
  EXPECT_EQ(checkFile("/tmp"), "not a regular file: /tmp");
  EXPECT_EQ(checkFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies"), "");
  // A relative path is named where it was looked for (a scene given as `night.toml` names
  // `nope.ies`, which alone does not say where).
  EXPECT_EQ(checkFile("nope/x.ies"),
            "file not found: " + (std::filesystem::current_path() / "nope/x.ies").lexically_normal().string());
}

}  // namespace
}  // namespace fogbeam
