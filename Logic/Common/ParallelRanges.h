#pragma once
// Work split over the machine's cores in contiguous ranges: the loops the stages run over every
// voxel of an image. Reductions go through per-thread slots (`thread` < parallelThreads()), so the
// results do not depend on the split.
#include <algorithm>
#include <cstddef>
#include <functional>
#include <thread>
#include <vector>

namespace brainshift {

/// The threads parallelRanges runs: the machine's cores, at most 8.
inline unsigned parallelThreads() { return std::max(1u, std::min(8u, std::thread::hardware_concurrency())); }

/// Runs body(begin, end, thread) over [0, count) on parallelThreads() threads, in contiguous
/// chunks. The body must not throw.
inline void parallelRanges(std::size_t count, const std::function<void(std::size_t, std::size_t, unsigned)>& body)
{
  const unsigned threads = parallelThreads();
  std::vector<std::thread> workers;
  for (unsigned t = 0; t < threads; ++t) {
    const std::size_t begin = count * t / threads, end = count * (t + 1) / threads;
    workers.emplace_back([&body, begin, end, t] { body(begin, end, t); });
  }
  for (auto& w : workers) w.join();
}

} // namespace brainshift
