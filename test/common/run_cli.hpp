// Runs the valvediag binary in a child process with a time limit, capturing stdout and stderr:
// for tests of commands (exit statuses, messages, kill -9). A hung child is killed, never waited
// for forever.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "text.hpp"

namespace valvediag::test {

// Starts `args` (args[0]: the program) with stdout and stderr into `out`; `env` changes the
// child's environment ("NAME=VALUE" sets, "-NAME" removes), `cwd` its working folder. With
// `own_group` the child leads a process group of its own, so that kill(-pid) ends what it started
// too (a browser's helper processes).
// Everything the child needs is built before fork(): a test may run a server thread (SimPlc),
// and an allocation in the child could wait for a lock that thread held at the fork, for ever.
// Between fork and exec the child makes only async-signal-safe calls.
inline pid_t spawn(const std::vector<std::string>& args, const std::filesystem::path& out,
                   const std::vector<std::string>& env = {}, const std::string& cwd = "",
                   bool own_group = false) {
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  std::vector<std::string> vars;
  for (char** e = environ; *e; ++e) vars.emplace_back(*e);
  for (const auto& e : env) {
    const bool remove = e.starts_with('-');
    const std::string name = remove ? e.substr(1) : e.substr(0, e.find('='));
    std::erase_if(vars, [&](const std::string& v) { return v.starts_with(name + "="); });
    if (!remove && e.find('=') != std::string::npos) vars.push_back(e);
  }
  std::vector<char*> envp;
  for (auto& v : vars) envp.push_back(v.data());
  envp.push_back(nullptr);
  const std::string path = out.string();
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (own_group) ::setpgid(0, 0);
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, 1);
    ::dup2(fd, 2);
    if (!cwd.empty() && ::chdir(cwd.c_str()) != 0) ::_exit(126);
    ::execve(argv[0], argv.data(), envp.data());
    ::_exit(127);
  }
  if (own_group && pid > 0) ::setpgid(pid, pid);  // also here: kill(-pid) works at once
  return pid;
}

// Exit status of the child, -2 when a signal ended it, or -1 after killing it when it outlives
// `limit_s`.
inline int wait_child(pid_t pid, double limit_s) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(limit_s);
  int status = 0;
  while (std::chrono::steady_clock::now() < end) {
    if (::waitpid(pid, &status, WNOHANG) == pid)
      return WIFEXITED(status) ? WEXITSTATUS(status) : -2;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ::kill(pid, SIGKILL);
  ::waitpid(pid, &status, 0);
  return -1;
}

struct CliResult {
  int status;
  std::string out;
};

// `bin` with `args`; the output (stdout and stderr together) goes through a numbered file in
// `tmp`, removed once read. `env`, `cwd`: as for spawn().
inline CliResult run_cli(const std::string& bin, const std::vector<std::string>& args,
                         const std::filesystem::path& tmp, double limit_s = 60.0,
                         const std::vector<std::string>& env = {}, const std::string& cwd = "") {
  static int n = 0;
  // The process id keeps test programs that ctest runs side by side (one binary, several
  // entries) off each other's files.
  const std::filesystem::path out =
      tmp / ("cli_out_" + std::to_string(::getpid()) + "_" + std::to_string(++n) + ".txt");
  std::vector<std::string> full{bin};
  full.insert(full.end(), args.begin(), args.end());
  const int st = wait_child(spawn(full, out, env, cwd), limit_s);
  std::string text = slurp(out);
  std::error_code ec;
  std::filesystem::remove(out, ec);  // one file per call would pile up over runs
  return {st, std::move(text)};
}

// The arguments `a` followed by `b`.
inline std::vector<std::string> with(std::vector<std::string> a,
                                     const std::vector<std::string>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

}  // namespace valvediag::test
