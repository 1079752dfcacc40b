#include "apps/interrupt.hpp"

#include <unistd.h>

#include <atomic>
#include <csignal>
#include <ctime>

namespace tissue::app {
namespace {

std::atomic<int> g_signal{0};  // lock-free: safe to touch in a signal handler
static_assert(std::atomic<int>::is_always_lock_free);
std::atomic<long long> g_first_ns{0};  // CLOCK_MONOTONIC of the first signal
static_assert(std::atomic<long long>::is_always_lock_free);

long long now_ns() {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);  // async-signal-safe
  return t.tv_sec * 1'000'000'000LL + t.tv_nsec;
}
struct sigaction g_old_int, g_old_term;

void write_stderr(const char* text) {
  size_t n = 0;
  while (text[n]) ++n;
  [[maybe_unused]] const ssize_t r = ::write(STDERR_FILENO, text, n);  // async-signal-safe
}

extern "C" void on_signal(int sig) {
  int expected = 0;
  if (g_signal.compare_exchange_strong(expected, sig)) {
    g_first_ns = now_ns();
    write_stderr(sig == SIGINT ? "\ntissue: SIGINT: stopping at the next boundary and writing the outputs "
                                 "(again to quit at once)\n"
                               : "\ntissue: SIGTERM: stopping at the next boundary and writing the outputs\n");
    return;
  }
  // `timeout` and process-group kills deliver one request twice at once:
  // only a signal a second after the first is a second request.
  if (now_ns() - g_first_ns.load() < 1'000'000'000LL) return;
  write_stderr("tissue: second signal: quitting now\n");
  ::_exit(128 + sig);
}

}  // namespace

InterruptGuard::InterruptGuard() {
  g_signal = 0;
  struct sigaction sa = {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;  // reads and writes in progress complete
  sigaction(SIGINT, &sa, &g_old_int);
  sigaction(SIGTERM, &sa, &g_old_term);
}

InterruptGuard::~InterruptGuard() {
  sigaction(SIGINT, &g_old_int, nullptr);
  sigaction(SIGTERM, &g_old_term, nullptr);
}

int InterruptGuard::signal() {
  return g_signal.load();
}

const char* InterruptGuard::signal_name() {
  switch (signal()) {
    case SIGINT:
      return "SIGINT";
    case SIGTERM:
      return "SIGTERM";
    default:
      return "no signal";
  }
}

}  // namespace tissue::app
