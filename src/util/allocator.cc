#include "util/allocator.h"

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace carmba {

void KeepFreedMemoryForReuse() {
#if defined(__GLIBC__)
  // Setting the trim threshold turns glibc's adaptive mmap threshold off, and with it at its
  // 128 kB default every matrix above it would be mapped and faulted in afresh instead:
  // allocations up to 32 MB (glibc's largest mmap threshold) come from the heap too.
  constexpr int kTrimThresholdBytes = 256 << 20;
  constexpr int kMmapThresholdBytes = 32 << 20;
  mallopt(M_TRIM_THRESHOLD, kTrimThresholdBytes);
  mallopt(M_MMAP_THRESHOLD, kMmapThresholdBytes);
#endif
}

}  // namespace carmba
