// A persistent team of threads for the cpu backend's TLED steps.
// TBB's parallel_for forks and joins once per pass; on the kidney (8,576
// elements) four passes of 10-40 us each spend much of their time in that
// fork/join, so 16 threads barely beat 2. The team instead starts its
// threads once, hands a whole advance (every step, every pass) to them in
// one job, and separates the passes with a spinning barrier (about a
// microsecond). Each member works on a fixed slice of the region
// (partition.hpp), the same slice every step, so its elements and nodes tend
// to stay in one core's cache (the threads are not pinned).
//
// Members: rank 0 is the thread that calls run(); ranks 1..size-1 are the
// team's own threads (created by the first caller, whose scheduling policy
// they inherit). Between jobs the last job's members spin for 100 us, the
// others not at all, then they sleep on a futex (std::atomic::wait), so an
// idle backend costs no CPU; a member that waits at a barrier for more than
// 300 us yields its core between looks (another member may have lost it),
// and after 2 ms sleeps too.
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
  /// members stay idle. If a barrier's `last` threw, rethrows it here. The
  /// job itself must not throw (a throw outside `last` ends the program:
  /// the other members would wait for it at the next barrier forever).
  /// One caller at a time; run() inside a job throws std::logic_error.
  template <class Job>
  void run(int active, const Job& job) {
    launch(active, [](const void* j, int rank) noexcept { (*static_cast<const Job*>(j))(rank); }, &job);
  }

  /// Inside a job: returns once all the job's members have called it (every
  /// member must call barrier the same number of times in a job). The last
  /// to arrive runs last() before releasing the others (so last() sees every
  /// member's writes and they see its). Returns false when a barrier's
  /// last() has thrown in this job: the members should then leave the job.
  /// A member that waits longer than 300 us yields its core between looks;
  /// after 2 ms it sleeps on a futex.
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
      release_barrier(gen);
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
  void wait_barrier(std::uint32_t gen);
  void release_barrier(std::uint32_t gen);
  void shut_down();

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
  std::atomic<int> barrier_sleepers_{0};      ///< members asleep on barrier_gen_
  std::atomic<int> done_sleepers_{0};         ///< the caller, asleep on done_
  std::atomic<bool> stop_{false};
  std::atomic<bool> running_{false};
};

/// The number of threads the cpu backend's team uses: TBB's current limit
/// (tbb::global_control, the process's CPU affinity mask, e.g. `taskset`),
/// at most the cores of the calling thread's affinity mask now, and at most
/// the environment's TISSUE_THREADS (which also caps TBB's threads for the
/// process's life). Throws std::invalid_argument naming a TISSUE_THREADS
/// that is not a whole number in 1..kMaxSize.
int default_team_size();
/// TISSUE_THREADS' value: 0 when unset or empty; throws as above.
int thread_cap(const char* text);

}  // namespace tissue::cpu
