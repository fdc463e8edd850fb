// Stopping a long run without losing it: the first SIGINT (Ctrl-C) or
// SIGTERM only asks the run to stop after the frame it is on, so that it can
// still write its outputs; a second one ends the process at once, for a user
// who will not wait for that.
#pragma once

#include <signal.h>

#include <csignal>
#include <initializer_list>

namespace emfusion::examples {

namespace detail {
// The handler runs on whichever thread the kernel picks, in the middle of
// any code: it may only set this, and the frame loop reads it.
inline volatile std::sig_atomic_t interrupt_signal = 0;

inline void on_interrupt(int sig) {
  if (interrupt_signal != 0) {
    // The second signal: its default action (termination), as soon as this
    // handler returns and unblocks it.
    std::signal(sig, SIG_DFL);
    std::raise(sig);
    return;
  }
  interrupt_signal = sig;
}
}  // namespace detail

/// Installs the handler for SIGINT and SIGTERM. A signal that the process
/// inherited as ignored stays ignored (a job started in the background by a
/// shell without job control must not stop on the terminal's Ctrl-C).
inline void catch_interrupts() {
  for (const int sig : {SIGINT, SIGTERM}) {
    struct sigaction previous {};
    if (sigaction(sig, nullptr, &previous) == 0 && previous.sa_handler == SIG_IGN) continue;
    struct sigaction action {};
    action.sa_handler = detail::on_interrupt;
    sigemptyset(&action.sa_mask);
    // Restart interrupted system calls: reads and writes of the run go on.
    action.sa_flags = SA_RESTART;
    sigaction(sig, &action, nullptr);
  }
}

/// The signal that asked the run to stop, or 0.
inline int interrupt_signal() { return detail::interrupt_signal; }

/// "SIGINT", "SIGTERM", or the number.
inline const char* signal_name(int sig) {
  switch (sig) {
    case SIGINT:
      return "SIGINT";
    case SIGTERM:
      return "SIGTERM";
    default:
      return "a signal";
  }
}

}  // namespace emfusion::examples
