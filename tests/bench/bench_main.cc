// The one main() of carmba_bench. Benchmark files (tests/bench/*_bench.cc) only register
// benchmarks; they must not define BENCHMARK_MAIN themselves.
#include <benchmark/benchmark.h>

BENCHMARK_MAIN();
