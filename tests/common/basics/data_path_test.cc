// Lookup order of the shipped data: $INDRIVE_DATA_DIR alone when set, else the installed
// share/indrive beside the executable, else the source tree.
#include "indrive/basics/data_path.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <fstream>

#include "testing.h"

namespace indrive {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

// Three roots that each hold a copy of the same relative file, plus one file only in the source.
class DataPathTest : public ::testing::Test {
 protected:
  void SetUp() override {
    env_root_ = dir_.path() / "override";
    prefix_ = dir_.path() / "prefix";
    source_ = dir_.path() / "source";
    write(env_root_ / kProfile, "env");
    write(prefix_ / "share/indrive" / kProfile, "installed");
    write(source_ / kProfile, "source");
    write(source_ / "envserver/data/towns/town01.nod.xml", "source-only");
    fs::create_directories(prefix_ / "bin");
  }

  static void write(const fs::path& path, const std::string& text) {
    fs::create_directories(path.parent_path());
    std::ofstream(path) << text;
  }
  static std::string read(const fs::path& path) {
    std::ifstream in(path);
    return std::string(std::istreambuf_iterator<char>(in), {});
  }

  static constexpr const char* kProfile = "deploy/dds/single_host.xml";
  testing::TempDir dir_{"indrive-data-path"};
  fs::path env_root_, prefix_, source_;
};

TEST_F(DataPathTest, EnvironmentVariableWinsOverEverything) {
  const DataSearch search{.env_value = env_root_.string(),
                          .executable = prefix_ / "bin/indrive-actor",
                          .source_dir = source_};
  EXPECT_EQ(read(find_data(kProfile, search)), "env");
  EXPECT_EQ(data_roots(search), std::vector<fs::path>{env_root_});
}

TEST_F(DataPathTest, EnvironmentVariableIsTheOnlyRootWhenSet) {
  // The file exists in the source tree, but a set override never falls back to it.
  const DataSearch search{.env_value = env_root_.string(), .source_dir = source_};
  try {
    find_data("envserver/data/towns/town01.nod.xml", search);
    FAIL() << "expected DataPathError";
  } catch (const DataPathError& error) {
    EXPECT_THAT(error.what(), HasSubstr("INDRIVE_DATA_DIR is set to"));
    EXPECT_THAT(error.what(), HasSubstr((env_root_ / "envserver/data").string()));
  }
}

TEST_F(DataPathTest, InstalledTreeBesideTheExecutableComesBeforeTheSourceTree) {
  const DataSearch search{.executable = prefix_ / "bin/indrive-actor", .source_dir = source_};
  EXPECT_EQ(read(find_data(kProfile, search)), "installed");
  const auto roots = data_roots(search);
  ASSERT_EQ(roots.size(), 2u);
  EXPECT_EQ(roots[0], prefix_ / "share/indrive");
  EXPECT_EQ(roots[1], source_);
}

TEST_F(DataPathTest, SourceTreeIsTheLastResort) {
  // A build tree (bin/ without share/indrive beside it) falls through to the source tree, and
  // so does a file the installed tree lacks.
  const DataSearch build_tree{.executable = dir_.path() / "build/bin/indrive-actor",
                              .source_dir = source_};
  EXPECT_EQ(read(find_data(kProfile, build_tree)), "source");
  const DataSearch installed{.executable = prefix_ / "bin/indrive-actor", .source_dir = source_};
  EXPECT_EQ(read(find_data("envserver/data/towns/town01.nod.xml", installed)), "source-only");
  // Folders are found as well as files.
  EXPECT_EQ(find_data("envserver/data", installed), source_ / "envserver/data");
}

TEST_F(DataPathTest, MissingEverywhereListsEveryPlaceTried) {
  const DataSearch search{.executable = prefix_ / "bin/indrive-actor", .source_dir = source_};
  try {
    find_data("deploy/configs/nope.yaml", search);
    FAIL() << "expected DataPathError";
  } catch (const DataPathError& error) {
    EXPECT_THAT(error.what(),
                HasSubstr((prefix_ / "share/indrive/deploy/configs/nope.yaml").string()));
    EXPECT_THAT(error.what(), HasSubstr((source_ / "deploy/configs/nope.yaml").string()));
    EXPECT_THAT(error.what(), HasSubstr("set $INDRIVE_DATA_DIR"));
  }
  EXPECT_THROW(find_data("anything", DataSearch{}), DataPathError);
}

TEST(DataPathProcessTest, ThisProcessFindsTheShippedProfile) {
  // The test binary runs from the build tree, so the source tree compiled in answers.
  if (std::getenv(kDataDirEnvVar) != nullptr) GTEST_SKIP() << "INDRIVE_DATA_DIR is set";
  const fs::path found = find_data("deploy/dds/single_host.xml");
  EXPECT_TRUE(fs::is_regular_file(found)) << found;
  EXPECT_EQ(fs::canonical(found),
            fs::canonical(testing::source_path("deploy/dds/single_host.xml")));
}

}  // namespace
}  // namespace indrive
