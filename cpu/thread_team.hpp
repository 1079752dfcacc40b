// A persistent team of threads for the cpu backend's TLED steps (issue 14).
// TBB's parallel_for forks and joins once per pass; on the kidney (8,576
// elements) four passes of 10-40 us each spend much of their time in that
// fork/join, so 16 threads barely beat 2. The team instead starts its
// threads once, hands a whole advance (every step, every pass) to them in
// one job, and separates the passes with a spinning barrier (about a
// microsecond). Each member works on a fixed slice of the region
// (partition.hpp), the same slice every step, so its elements and nodes stay
// in its core's cache.
//
// Members: rank 0 is the thread that calls run(); ranks 1..size-1 are the
// team's own threads. Between jobs they spin for kIdleSpin, then sleep on a
// futex (std::atomic::wait), so an idle backend costs no CPU.
#pragma once

#include <atomic>
#include <cstdint>
#include <exception>
#include <thread>
#include <vector>

namespace tissue::cpu {

class ThreadTeam {
 public:
  /// A team of `size` members (1..kMaxSize): the caller and size - 1 threads.
  static constexpr int kMaxSize = 255;
  explicit ThreadTeam(int size);
  ~ThreadTeam();
  ThreadTeam(const ThreadTeam&) = delete;
  ThreadTeam& operator=(const ThreadTeam&) = delete;

  int size() const { return size_; }

  /// Runs job(rank) on ranks 0..active-1 (1 <= active <= size; rank 0 on the
  /// calling thread) and returns when every one has returned. The other
  /// members stay idle. If a barrier's `last` threw, rethrows it here.
  /// One caller at a time; not re-entrant.
  template <class Job>
  void run(int active, const Job& job) {
    launch(active, [](const void* j, int rank) { (*static_cast<const Job*>(j))(rank); }, &job);
  }

  /// Inside a job: returns once all the job's members have called it. The
  /// last to arrive runs last() before releasing the others (so last() sees
  /// every member's writes and they see its). Returns false when a barrier's
  /// last() has thrown in this job: the members should then leave the job.
  template <class Last>
  bool barrier(const Last& last) {
    const std::uint32_t gen = barrier_gen_.load(std::memory_order_acquire);
    if (arrived_.fetch_add(1, std::memory_order_acq_rel) + 1 == active_) {
      arrived_.store(0, std::memory_order_relaxed);
      if (!failed_.load(std::memory_order_relaxed)) {
        try {
          last();
        } catch (...) {
          error_ = std::current_exception();
          failed_.store(true, std::memory_order_relaxed);
        }
      }
      barrier_gen_.store(gen + 1, std::memory_order_release);
    } else {
      wait_barrier(gen);
    }
    return !failed_.load(std::memory_order_relaxed);
  }
  bool barrier() {
    return barrier([] {});
  }

 private:
  using JobFn = void (*)(const void*, int);
  void launch(int active, JobFn fn, const void* job);
  void worker(int rank);
  void wait_barrier(std::uint32_t gen) const;

  int size_;
  std::vector<std::thread> threads_;
  JobFn fn_ = nullptr;
  const void* job_ = nullptr;
  int active_ = 1;          ///< members of the current job (written before job_word_ is published)
  std::exception_ptr error_;
  std::atomic<bool> failed_{false};
  /// (job generation << 8) | active members, published once per job; a
  /// worker reads both from this one word, so it never mixes two jobs' counts
  alignas(64) std::atomic<std::uint64_t> job_word_{0};
  alignas(64) std::atomic<int> done_{0};      ///< workers finished with the current job
  alignas(64) std::atomic<int> arrived_{0};   ///< members at the current barrier
  alignas(64) std::atomic<std::uint32_t> barrier_gen_{0};
  alignas(64) std::atomic<int> sleepers_{0};  ///< workers asleep on job_word_
  std::atomic<bool> stop_{false};
};

/// The number of threads the cpu backend's team uses: TBB's current limit
/// (tbb::global_control, the process's CPU affinity mask, e.g. `taskset`).
int default_team_size();

}  // namespace tissue::cpu
