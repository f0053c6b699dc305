#include "stop_signal.hpp"

#include <csignal>

namespace valvediag::cli {

namespace {
std::atomic<bool> g_stop{false};
extern "C" void on_stop(int) {
  g_stop.store(true);
}
}  // namespace

std::atomic<bool>& install_stop_signals() {
  struct sigaction sa {};
  sa.sa_handler = on_stop;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  std::signal(SIGPIPE, SIG_IGN);
  return g_stop;
}

}  // namespace valvediag::cli
