// SIGINT (Ctrl-C) and SIGTERM as a request to stop cleanly. While an
// InterruptGuard lives, the first of those signals only sets a flag: the
// long commands (run, bench, reference, tradeoff) check it at their next
// boundary (a haptic tick, a measurement, a convergence check, a sweep row),
// write their summary and complete outputs, and exit with 128 + the signal
// (130 for SIGINT, 143 for SIGTERM), as a shell expects of a process ended
// by that signal. A second signal (a second or more after the first: tools
// such as `timeout` deliver one request twice) ends the process at once with
// the same code: the files already renamed into place are whole
// (io/atomic_file.hpp), at most a ".part" file is left.
#pragma once

namespace tissue::app {

class InterruptGuard {
 public:
  /// Installs the handlers (sigaction) and clears the flag.
  InterruptGuard();
  /// Restores the handlers that were installed before.
  ~InterruptGuard();
  InterruptGuard(const InterruptGuard&) = delete;
  InterruptGuard& operator=(const InterruptGuard&) = delete;

  /// The signal received (SIGINT or SIGTERM), 0 while none was.
  static int signal();
  /// True once a signal was received.
  static bool requested() { return signal() != 0; }
  /// 128 + signal(): the exit code of a command it stopped.
  static int exit_code() { return 128 + signal(); }
  /// "SIGINT" / "SIGTERM" / "no signal".
  static const char* signal_name();
};

}  // namespace tissue::app
