// Short view ids (io/image_files.h ShortViewIds): what tables, CSVs and result.json name a view by.
#include <gtest/gtest.h>

#include "io/image_files.h"

namespace carmba {
namespace {

using Ids = std::vector<std::string>;

TEST(ShortViewIds, FileStemsAndFrames) {
  EXPECT_EQ(ShortViewIds({"/data/run/v_m05_m15.png", "/data/run/a.b.tif", "rel/x.dcm#frame3"}),
            (Ids{"v_m05_m15", "a.b", "x#frame3"}));
  EXPECT_EQ(ShortViewIds({"/d/run.dcm#frame1", "/d/run.dcm#frame2"}),
            (Ids{"run#frame1", "run#frame2"}));
  EXPECT_EQ(ShortViewIds({}), Ids{});
}

TEST(ShortViewIds, SameStemInTwoDirectoriesKeepsTheDirectories) {
  EXPECT_EQ(ShortViewIds({"/data/lao/v1.png", "/data/rao/v1.png", "/data/rao/v2.png"}),
            (Ids{"lao/v1", "rao/v1", "rao/v2"}));
  EXPECT_EQ(ShortViewIds({"/data/a/x/v1.png", "/data/b/v1.png"}), (Ids{"a/x/v1", "b/v1"}));
}

TEST(ShortViewIds, NamesDifferingOnlyInTheExtensionStayWhole) {
  EXPECT_EQ(ShortViewIds({"/d/v1.png", "/d/v1.tif"}), (Ids{"/d/v1.png", "/d/v1.tif"}));
}

}  // namespace
}  // namespace carmba
