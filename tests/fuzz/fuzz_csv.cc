// Fuzz target `csv` (fuzz_main.cc): carmba::ReadCsv (util/csv.h) and the table's typed accessors on
// every cell.
#include "fuzz_target.h"
#include "fuzz_util.h"
#include "util/csv.h"

namespace {

int FuzzCsv(const uint8_t* data, size_t size) {
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

}  // namespace

CARMBA_FUZZ_TARGET(csv, FuzzCsv, nullptr)
