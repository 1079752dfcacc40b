#include "cpu/thread_team.hpp"

#include <fmt/format.h>
#include <sched.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <stdexcept>

namespace tissue::cpu {
namespace {

using Clock = std::chrono::steady_clock;

/// How long an idle worker spins for the next job before it sleeps: longer
/// than the gap between a tick's advance and its reduce, far shorter than
/// the haptic loop's 1 ms period (spinning for it would keep every core busy).
constexpr auto kIdleSpin = std::chrono::microseconds(100);
/// How a member waits at a barrier (and the caller for the job's end): it
/// spins for kBarrierSpin (a pass takes microseconds, the contact stage in a
/// barrier's last() tens of them), then yields its core between looks until
/// kBarrierYield (a longer wait means a member lost its core, maybe to this
/// very thread), then sleeps on a futex. (Yielding after 20 us instead gave
/// 1.2-1.8 ms p99 haptic ticks on a 2-core machine: a yield hands the core
/// to any runnable thread, such as a TBB worker Embree woke, for a whole
/// time slice.)
constexpr auto kBarrierSpin = std::chrono::microseconds(300);
constexpr auto kBarrierYield = std::chrono::microseconds(2000);

inline void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__)
  asm volatile("yield");
#endif
}

/// Waits until a != old: spins for `spin`, then yields between looks until
/// `yield` has passed since the start, then sleeps on a futex
/// (std::atomic::wait), counted in `sleepers` so that the writer knows to
/// notify. Returns the new value.
template <class V>
V wait_for_change(const std::atomic<V>& a, V old, Clock::duration spin, Clock::duration yield,
                  std::atomic<int>& sleepers) {
  V v;
  const auto start = Clock::now();
  bool yielding = false;
  for (int k = 0; (v = a.load(std::memory_order_acquire)) == old; ++k) {
    if (yielding) {
      std::this_thread::yield();
    } else {
      cpu_relax();
    }
    if ((k & 63) != 63) continue;
    const auto waited = Clock::now() - start;
    if (waited > yield) {
      sleepers.fetch_add(1, std::memory_order_seq_cst);
      a.wait(old, std::memory_order_seq_cst);
      sleepers.fetch_sub(1, std::memory_order_seq_cst);
    } else if (waited > spin) {
      yielding = true;
    }
  }
  return v;
}

/// After a writer changed `a` (seq_cst): wakes its sleepers, if any.
template <class V>
void wake(std::atomic<V>& a, const std::atomic<int>& sleepers) {
  if (sleepers.load(std::memory_order_seq_cst) > 0) a.notify_all();
}

}  // namespace

int thread_cap(const char* text) {
  if (text == nullptr || *text == '\0') return 0;
  char* end = nullptr;
  errno = 0;
  const long n = std::strtol(text, &end, 10);
  if (errno != 0 || end == text || *end != '\0' || n < 1 || n > ThreadTeam::kMaxSize)
    throw std::invalid_argument(fmt::format("TISSUE_THREADS='{}' must be a whole number in 1..{} (the threads the cpu "
                                            "backend may use), or unset",
                                            text, ThreadTeam::kMaxSize));
  return int(n);
}

int default_team_size() {
  // TISSUE_THREADS caps TBB's threads too, for the process's life (read once)
  static const int cap = [] {
    const int n = thread_cap(std::getenv("TISSUE_THREADS"));
    if (n > 0) static const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(n));
    return n;
  }();
  const auto limit = tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism);
  int n = std::min(int(limit), tbb::this_task_arena::max_concurrency());
  if (cap > 0) n = std::min(n, cap);
  // the calling thread's CPU affinity mask now: TBB reads the process's once, when it loads, so a mask narrowed
  // later (a worker given its share of the cores) would leave a team larger than its cores, spinning at barriers
  cpu_set_t set;
  CPU_ZERO(&set);
  if (::sched_getaffinity(0, sizeof set, &set) == 0 && CPU_COUNT(&set) > 0) n = std::min(n, CPU_COUNT(&set));
  return std::clamp(n, 1, ThreadTeam::kMaxSize);
}

ThreadTeam::ThreadTeam(int size) : size_(size) {
  if (size < 1 || size > kMaxSize) throw std::invalid_argument("ThreadTeam: size must be in 1..255");
  threads_.reserve(std::size_t(size - 1));
  try {
    for (int r = 1; r < size; ++r) threads_.emplace_back([this, r] { worker(r); });
  } catch (...) {  // (the system refused a thread) stop the ones started
    shut_down();
    throw;
  }
}

ThreadTeam::~ThreadTeam() { shut_down(); }

void ThreadTeam::shut_down() {
  stop_.store(true, std::memory_order_seq_cst);
  job_word_.fetch_add(std::uint64_t(1) << 8, std::memory_order_seq_cst);
  job_word_.notify_all();
  for (std::thread& t : threads_) t.join();
  threads_.clear();
}

void ThreadTeam::launch(int active, JobFn fn, const void* job) {
  if (active < 1 || active > size_) throw std::invalid_argument("ThreadTeam::run: active members outside 1..size");
  if (running_.exchange(true)) throw std::logic_error("ThreadTeam::run: called while a job runs (not re-entrant)");
  fn_ = fn;
  job_ = job;
  active_ = active;
  failed_.store(false, std::memory_order_relaxed);
  error_ = nullptr;
  done_.store(0, std::memory_order_relaxed);
  if (active > 1) {
    const std::uint64_t word = ((job_word_.load(std::memory_order_relaxed) >> 8) + 1) << 8 | std::uint64_t(active);
    job_word_.store(word, std::memory_order_seq_cst);
    wake(job_word_, sleepers_);
  }
  fn(job, 0);  // noexcept (run's trampoline)
  for (int d = 0; d != active - 1;) d = wait_for_change(done_, d, kBarrierSpin, kBarrierYield, done_sleepers_);
  running_.store(false);
  if (error_) std::rethrow_exception(error_);
}

void ThreadTeam::worker(int rank) {
  std::uint64_t seen = 0;
  bool was_member = false;
  for (;;) {
    // a member of the last job spins a little for the next; the others sleep at once
    const Clock::duration spin = was_member ? Clock::duration(kIdleSpin) : Clock::duration::zero();
    seen = wait_for_change(job_word_, seen, spin, spin, sleepers_);
    if (stop_.load(std::memory_order_acquire)) return;
    was_member = rank < int(seen & 0xff);
    if (was_member) {
      fn_(job_, rank);
      done_.fetch_add(1, std::memory_order_seq_cst);
      wake(done_, done_sleepers_);
    }
  }
}

void ThreadTeam::wait_barrier(std::uint32_t gen) {
  wait_for_change(barrier_gen_, gen, kBarrierSpin, kBarrierYield, barrier_sleepers_);
}

void ThreadTeam::release_barrier(std::uint32_t gen) {
  barrier_gen_.store(gen + 1, std::memory_order_seq_cst);
  wake(barrier_gen_, barrier_sleepers_);
}

}  // namespace tissue::cpu
