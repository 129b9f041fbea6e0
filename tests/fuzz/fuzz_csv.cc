// libFuzzer harness: carmba::ReadCsv (util/csv.h) and the table's typed accessors on every cell.
#include "fuzz_util.h"
#include "util/csv.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("in.csv", data, size);
  auto t = carmba::ReadCsv(path);
  if (!t.ok()) return 0;
  for (size_t r = 0; r < t->rows.size() && r < 64; ++r) {
    for (const auto& name : t->header) {
      (void)t->Number(static_cast<int>(r), name);
      (void)t->Integer(static_cast<int>(r), name);
    }
  }
  return 0;
}
