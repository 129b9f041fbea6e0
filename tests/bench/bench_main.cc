// The one main() of carmba_bench. Benchmark files (tests/bench/*_bench.cc) only register
// benchmarks; they must not define BENCHMARK_MAIN themselves. The heap is set up as the carmba
// command sets it (util/allocator.h), so that a benchmark times what the command runs.
#include <benchmark/benchmark.h>

#include "util/allocator.h"

int main(int argc, char** argv) {
  carmba::KeepFreedMemoryForReuse();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
