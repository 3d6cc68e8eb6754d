#pragma once
// The process's memory: large buffers on transparent huge pages.
//
// An update allocates and first touches a few gigabytes a scan (volumes of 4 M voxels, fields of
// 12 M doubles, each made anew). With 4 KiB pages each first touch is a page fault, and in a
// virtual machine a page fault is dear: on the 2-vCPU VM of Testing/Benchmarks/results/session,
// `brainshift warp` spent 1.6 s of its 4.1 s in the kernel, and a later scan of a watch session
// took 8.3-10.0 s against 6.3-6.4 s on huge pages (README, "The operating room's timeline").
// glibc puts its heap and large blocks on 2 MiB transparent huge pages (madvise) when the tunable
// glibc.malloc.hugetlb is 1; tunables are read when a process starts, so the program runs itself
// again with it set.

namespace brainshift {

/// Called first in main(): when GLIBC_TUNABLES does not yet say glibc.malloc.hugetlb, sets it to 1
/// and executes this program again with the same arguments (same process id; the workers it
/// starts inherit the setting). Returns when nothing is to be done (the tunable already set, by
/// this function or by the user: glibc.malloc.hugetlb=0 keeps 4 KiB pages; not glibc; Linux
/// without transparent huge pages), or when the program cannot be executed again (then it runs
/// on as it is: the setting is a matter of speed, never of results).
void restartWithHugePageAllocations(char** argv);

/// Called after restartWithHugePageAllocations: freed blocks of up to 32 MiB (a volume of 4 M
/// floats is 16 MiB) stay in the heap for the next allocation instead of going back to the kernel,
/// whose fresh pages it must clear again on first touch (perf on a watch session of three scans:
/// 12 % of the samples in the kernel clearing pages). glibc's mallopt: the threshold above which a
/// block gets its own mapping (the largest glibc allows on 64 bits), and no trimming of the heap's
/// top below 2 GiB. The process keeps its peak heap resident; results are the same.
void keepFreedMemoryForReuse();

/// Whether this process's allocations go on transparent huge pages (GLIBC_TUNABLES says
/// glibc.malloc.hugetlb=1 and the kernel's policy allows them); report.json records it beside the times.
bool hugePageAllocations();

} // namespace brainshift
