// A running `valvediag serve` for the tests that talk to it over HTTP (test_serve_http.cpp) or
// drive a browser at it (test_workbench_browser.cpp): started on a free port, its address and
// token read from what it prints, killed by the destructor if the test did not stop it.
// Include it last: it includes <httplib.h> (see below).
#pragma once

#include <doctest/doctest.h>
#include <signal.h>
#include <sys/wait.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "../common/run_cli.hpp"
#include "../common/text.hpp"

// Last: its <resolv.h> defines `_res`, which breaks Eigen headers included after it.
#include <httplib.h>

namespace valvediag::test {

struct ServeProcess {
  pid_t pid = -1;
  std::filesystem::path out;
  int port = 0;
  std::string token;
  // args: the command and its options ({"serve", "loop.csv", "--port", "0"}); limit_s: how long
  // it may take to print its address; env: changes to its environment, as for spawn().
  ServeProcess(const std::string& bin, const std::vector<std::string>& args,
               const std::filesystem::path& tmp, const std::string& tag, double limit_s = 30.0,
               const std::vector<std::string>& env = {}) {
    out = tmp / ("serve_" + std::to_string(::getpid()) + "_" + tag + ".txt");
    std::vector<std::string> full{bin};
    full.insert(full.end(), args.begin(), args.end());
    pid = spawn(full, out, env);
    // Its first lines: the address with the port it picked, then the token. (No std::regex:
    // GCC 12 warns inside it under the sanitizers' -O1, and warnings are errors.)
    const std::string addr = "http://127.0.0.1:", tok = "token: ";
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(limit_s);
    while (std::chrono::steady_clock::now() < end) {
      const std::string text = slurp(out);
      if (const auto a = text.find(addr), slash = text.find('/', a + addr.size());
          a != std::string::npos && slash != std::string::npos) {
        port = std::atoi(text.substr(a + addr.size(), slash - a - addr.size()).c_str());
        if (const auto t = text.find(tok); t != std::string::npos)
          token = text.substr(t + tok.size(), 32);
        return;
      }
      if (::waitpid(pid, nullptr, WNOHANG) == pid) {
        pid = -1;
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    if (pid > 0) {  // a constructor that throws runs no destructor: end it here
      ::kill(pid, SIGKILL);
      ::waitpid(pid, nullptr, 0);
      pid = -1;
    }
    FAIL("valvediag serve did not print its address: " << slurp(out));
  }
  ServeProcess(const ServeProcess&) = delete;
  ServeProcess& operator=(const ServeProcess&) = delete;
  // Ctrl-C: its exit status (-1 when it had to be killed).
  int stop() {
    if (pid <= 0) return -3;
    ::kill(pid, SIGINT);
    const int st = wait_child(pid, 30.0);
    pid = -1;
    return st;
  }
  ~ServeProcess() {
    if (pid > 0) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, nullptr, 0);
    }
  }
  httplib::Client client() const {
    httplib::Client c("127.0.0.1", port);
    c.set_connection_timeout(5, 0);
    c.set_read_timeout(120, 0);  // the verdict fits the loop: seconds, more under sanitizers
    c.set_write_timeout(5, 0);
    return c;
  }
};

}  // namespace valvediag::test
