// The timing loop of the Pinocchio C++ peers (pinocchio_bench.cpp, pinocchio_tree_bench.cpp),
// the same as the C harness uses for the generated code: cycle over K precomputed inputs,
// CLOCK_MONOTONIC, outputs summed into a volatile sink so that no call is optimised away.
// Header-only, for one translation unit per program.
#ifndef KDG_BENCH_TIMING_HPP
#define KDG_BENCH_TIMING_HPP

#include <algorithm>
#include <cstdio>
#include <time.h>
#include <vector>

static volatile double sink;

static double now_ns()
{
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec * 1e9 + ts.tv_nsec;
}

// One timed repetition runs `iters` calls cycling over the K inputs; the iteration count is
// calibrated once so that a repetition lasts about target_ns (long enough to swamp the
// clock's resolution, short enough that a noisy neighbour spoils few of them). Prints
// "time NAME t1 ... tR" (ns per call in each repetition): Python pools them over interleaved
// runs.
template<typename Body>
static void measure(const char * name, long K, int repeats, double target_ns, Body body)
{
  long iters = 16;
  for (;;)
  {
    double t0 = now_ns();
    double acc = 0;
    for (long i = 0; i < iters; ++i)
      acc += body(i % K);
    sink = sink + acc;
    double dt = now_ns() - t0;
    if (dt > 0.2 * target_ns || iters > (1L << 30))
    {
      iters = std::max(1L, (long)(iters * target_ns / std::max(dt, 1.0)));
      break;
    }
    iters *= 4;
  }
  std::vector<double> per_call;
  for (int r = 0; r < repeats; ++r)
  {
    double acc = 0;
    long k = 0;
    double t0 = now_ns();
    for (long i = 0; i < iters; ++i)
    {
      acc += body(k);
      if (++k == K)
        k = 0;
    }
    double dt = now_ns() - t0;
    sink = sink + acc;
    per_call.push_back(dt / iters);
  }
  std::printf("time %s", name);
  for (double t : per_call)
    std::printf(" %.3f", t);
  std::printf("\n");
}

#endif
