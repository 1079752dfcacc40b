#include "cpu/thread_team.hpp"

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <stdexcept>

namespace tissue::cpu {
namespace {

/// How long an idle worker spins for the next job before it sleeps: longer
/// than the gap between a tick's advance and its reductions, far shorter
/// than the haptic loop's 1 ms period.
constexpr auto kIdleSpin = std::chrono::microseconds(100);
/// Barrier spins before a waiting member starts yielding its core (only
/// matters when the machine has fewer free cores than the team has members).
constexpr int kBarrierSpins = 1 << 14;

inline void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__)
  asm volatile("yield");
#endif
}

}  // namespace

int default_team_size() {
  const auto limit = tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism);
  return std::clamp(std::min(int(limit), tbb::this_task_arena::max_concurrency()), 1, ThreadTeam::kMaxSize);
}

ThreadTeam::ThreadTeam(int size) : size_(size) {
  if (size < 1 || size > kMaxSize) throw std::invalid_argument("ThreadTeam: size must be in 1..255");
  threads_.reserve(std::size_t(size - 1));
  for (int r = 1; r < size; ++r) threads_.emplace_back([this, r] { worker(r); });
}

ThreadTeam::~ThreadTeam() {
  stop_.store(true, std::memory_order_seq_cst);
  job_word_.fetch_add(std::uint64_t(1) << 8, std::memory_order_seq_cst);
  job_word_.notify_all();
  for (std::thread& t : threads_) t.join();
}

void ThreadTeam::launch(int active, JobFn fn, const void* job) {
  if (active < 1 || active > size_) throw std::invalid_argument("ThreadTeam::run: active members outside 1..size");
  fn_ = fn;
  job_ = job;
  active_ = active;
  failed_.store(false, std::memory_order_relaxed);
  error_ = nullptr;
  done_.store(0, std::memory_order_relaxed);
  if (active > 1) {
    const std::uint64_t word = ((job_word_.load(std::memory_order_relaxed) >> 8) + 1) << 8 | std::uint64_t(active);
    job_word_.store(word, std::memory_order_seq_cst);
    if (sleepers_.load(std::memory_order_seq_cst) > 0) job_word_.notify_all();
  }
  fn(job, 0);
  for (int spins = 0; done_.load(std::memory_order_acquire) != active - 1; ++spins) {
    cpu_relax();
    if (spins > kBarrierSpins) std::this_thread::yield();
  }
  if (error_) std::rethrow_exception(error_);
}

void ThreadTeam::worker(int rank) {
  std::uint64_t seen = 0;
  for (;;) {
    std::uint64_t word = job_word_.load(std::memory_order_acquire);
    if (word == seen) {
      const auto until = std::chrono::steady_clock::now() + kIdleSpin;
      for (int k = 0; (word = job_word_.load(std::memory_order_acquire)) == seen; ++k) {
        cpu_relax();
        if ((k & 255) == 255 && std::chrono::steady_clock::now() > until) {
          sleepers_.fetch_add(1, std::memory_order_seq_cst);
          job_word_.wait(seen, std::memory_order_seq_cst);
          sleepers_.fetch_sub(1, std::memory_order_seq_cst);
        }
      }
    }
    seen = word;
    if (stop_.load(std::memory_order_acquire)) return;
    if (rank < int(word & 0xff)) {
      fn_(job_, rank);
      done_.fetch_add(1, std::memory_order_release);
    }
  }
}

void ThreadTeam::wait_barrier(std::uint32_t gen) const {
  for (int spins = 0; barrier_gen_.load(std::memory_order_acquire) == gen; ++spins) {
    cpu_relax();
    if (spins > kBarrierSpins) std::this_thread::yield();
  }
}

}  // namespace tissue::cpu
