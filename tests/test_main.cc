// The one main() of the test executables: GoogleTest's, with the heap set up as the carmba
// command sets it (util/allocator.h), so that the engine runs in the tests as it runs for users.
#include <gtest/gtest.h>

#include "util/allocator.h"

int main(int argc, char** argv) {
  carmba::KeepFreedMemoryForReuse();
  testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
