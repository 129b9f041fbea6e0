// The heap of a process that solves bundle adjustments.
#pragma once

namespace carmba {

// Keeps freed heap memory in the process for the next allocation. glibc gives the top of the heap
// back to the kernel once 128 kB are free there, so the matrices of every solve (freed, then
// allocated again by the next re-solve, fold or view) come back as fresh pages, each a page fault
// and a page of zeros: about 230 faults per joint solve, a third of its time
// (tests/bench/joint_bench.cc, JointSelfChecks). With a trim threshold of 256 MB, and blocks up
// to 32 MB taken from the heap rather than mapped one by one, they are reused.
// For executables (the carmba command, the tests, the benchmarks), not for a library inside another
// program's process; a no-op where the C library is not glibc.
void KeepFreedMemoryForReuse();

}  // namespace carmba
