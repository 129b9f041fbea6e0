// Input parsing in util/: numbers, CSV and YAML edge cases that must be errors, not values.
#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <string>

#include "util/csv.h"
#include "util/file_util.h"
#include "util/yaml_reader.h"
#include "scratch.h"

namespace carmba {
namespace {

TEST(ParseFiniteDouble, DecimalOnly) {
  double v = 0;
  EXPECT_TRUE(ParseFiniteDouble(" -1.5e-3 ", &v));
  EXPECT_DOUBLE_EQ(v, -1.5e-3);
  EXPECT_TRUE(ParseFiniteDouble("20", &v));
  for (const char* bad : {"0x10", "inf", "-inf", "nan", "1.0f", "1,5", "", "e", "1e400"}) {
    EXPECT_FALSE(ParseFiniteDouble(bad, &v)) << bad;
  }
}

// The one parser of a view name's `#frameN`: the last one counts, the file keeps any other '#'.
TEST(SplitFrameSuffix, FileAndSuffix) {
  FrameName f = SplitFrameSuffix("dir/run#2.dcm#frame12");
  EXPECT_EQ(f.file, "dir/run#2.dcm");
  EXPECT_EQ(f.suffix, "#frame12");
  f = SplitFrameSuffix("dir/a.dcm");
  EXPECT_EQ(f.file, "dir/a.dcm");
  EXPECT_EQ(f.suffix, "");
}

TEST(Csv, ByteOrderMarkIsNotPartOfTheFirstField) {
  auto t = ParseCsv("\xEF\xBB\xBF# exported\nid,x\n1,2.5\n", "bom.csv");
  ASSERT_TRUE(t.ok()) << t.status().message();
  ASSERT_EQ(t->header.size(), 2u);
  EXPECT_EQ(t->header[0], "id");
  EXPECT_DOUBLE_EQ(*t->Number(0, "x"), 2.5);
}

TEST(Csv, HexadecimalValueIsAnErrorNamingTheLine) {
  auto t = ParseCsv("id,x\n1,0x10\n", "hex.csv");
  ASSERT_TRUE(t.ok());
  auto v = t->Number(0, "x");
  ASSERT_FALSE(v.ok());
  EXPECT_NE(v.status().message().find("hex.csv:2"), std::string::npos) << v.status().message();
}

class YamlFile : public ::testing::Test {
 protected:
  std::string Write(const std::string& name, const std::string& text) {
    const std::string path = dir_ + "/" + name;
    std::ofstream(path) << text;
    return path;
  }
  const test::ScratchDir scratch_{"util_test"};
  const std::string dir_ = scratch_.path();
};

TEST_F(YamlFile, RepeatedKeyIsAnErrorNamingItsLine) {
  YamlMap m = YamlMap::Load(Write("dup.yaml", "a: 1\nb: 2\na: 3\n"));
  ASSERT_FALSE(m.status().ok());
  EXPECT_NE(m.status().message().find("dup.yaml:3"), std::string::npos) << m.status().message();
  EXPECT_NE(m.status().message().find("'a'"), std::string::npos);
}

TEST_F(YamlFile, RepeatedNestedKeyIsAnError) {
  YamlMap m = YamlMap::Load(Write("dup2.yaml", "loss:\n  type: huber\n  type: cauchy\n"));
  ASSERT_TRUE(m.status().ok());
  YamlMap& loss = m.Map("loss");
  std::string type;
  loss.Get("type", &type);
  const Status s = m.Finish();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("dup2.yaml:3"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("loss.type"), std::string::npos) << s.message();
}

// An unknown key is named before a missing required key it may be a typo of (reported: typo
// `sigma_pz` gave "key 'sigma_px': missing" at line 1), both when the parser stops at the missing
// key (reads status()) and when it reads on to Finish().
TEST(YamlKeys, MisspeltRequiredKeyIsNamedAsUnknownWithTheSuggestion) {
  const char* kText = "name: p\nsigma_pz: 0.3\n";
  {
    YamlMap m(YAML::Load(kText), "p.yaml");
    double sigma = 0;
    std::string name;
    m.Get("name", &name);
    m.Get("sigma_px", &sigma, /*required=*/true);
    ASSERT_FALSE(m.status().ok());  // a parser that stops here
    EXPECT_EQ(m.status().message(),
              "p.yaml:2: unknown key 'sigma_pz'; did you mean 'sigma_px'? (a required key)");
  }
  // A key unlike the missing one: still reported before the missing key, by Finish().
  YamlMap m(YAML::Load("name: p\nfrobnicate: 1\n"), "q.yaml");
  double sigma = 0;
  std::string name;
  m.Get("name", &name);
  m.Get("sigma_px", &sigma, true);
  EXPECT_NE(m.status().message().find("'sigma_px': missing"), std::string::npos);
  const Status s = m.Finish();
  EXPECT_EQ(s.message().rfind("q.yaml:2: unknown key 'frobnicate'", 0), 0u) << s.message();
  // Nested maps too, and the plain unknown-key message suggests the closest known key.
  YamlMap n(YAML::Load("solver:\n  max_iteratons: 5\n"), "c.yaml");
  int it = 0;
  n.Map("solver").Get("max_iterations", &it);
  const Status t = n.Finish();
  EXPECT_NE(t.message().find("c.yaml:2: unknown key 'solver.max_iteratons'; did you mean "
                             "'max_iterations'?"),
            std::string::npos)
      << t.message();
  // Without a typo, a missing key is still named as missing.
  YamlMap k(YAML::Load("name: p\n"), "r.yaml");
  k.Get("name", &name);
  k.Get("sigma_px", &sigma, true);
  EXPECT_NE(k.Finish().message().find("key 'sigma_px': missing"), std::string::npos);
}

TEST_F(YamlFile, DirectoryIsAnErrorNotACrash) {
  YamlMap m = YamlMap::Load(dir_);
  ASSERT_FALSE(m.status().ok());
  EXPECT_NE(m.status().message().find("is a directory"), std::string::npos);
}

}  // namespace
}  // namespace carmba
