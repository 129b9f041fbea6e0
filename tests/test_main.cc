// The one main() of the test executables: GoogleTest's, with the heap set up as the carmba
// command sets it (util/allocator.h), so that the engine runs in the tests as it runs for users.
//
// ctest runs one suite per process (tests/CMakeLists.txt, carmba_add_test_suites) and sets
// CARMBA_TEST_ALL_SKIPPED_EXIT=77: when every test that ran was skipped (GTEST_SKIP: Chromium,
// Slurm or matplotlib absent) and none failed, the process exits with that code, which ctest
// reports as a skipped test instead of a passed one.
#include <gtest/gtest.h>

#include <cstdlib>

#include "util/allocator.h"

int main(int argc, char** argv) {
  carmba::KeepFreedMemoryForReuse();
  testing::InitGoogleTest(&argc, argv);
  const int rc = RUN_ALL_TESTS();
  const testing::UnitTest& run = *testing::UnitTest::GetInstance();
  const char* skipped_exit = std::getenv("CARMBA_TEST_ALL_SKIPPED_EXIT");
  if (rc == 0 && skipped_exit != nullptr && run.test_to_run_count() > 0 &&
      run.skipped_test_count() == run.test_to_run_count()) {
    return std::atoi(skipped_exit);
  }
  return rc;
}
