#include "valvediag/report/gnuplot.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <vector>

extern char** environ;

namespace valvediag {

namespace {

// A file descriptor closed when it goes out of scope.
struct Fd {
  int fd = -1;
  Fd() = default;
  explicit Fd(int f) : fd(f) {}
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  ~Fd() { reset(); }
  void reset() {
    if (fd >= 0) ::close(fd);
    fd = -1;
  }
};

void make_pipe(Fd& read_end, Fd& write_end) {
  int p[2];
  if (::pipe2(p, O_CLOEXEC) != 0)
    throw GnuplotError(std::string("cannot create a pipe for gnuplot: ") + std::strerror(errno));
  read_end.fd = p[0];
  write_end.fd = p[1];
}

void set_nonblocking(int fd) {
  const int flags = ::fcntl(fd, F_GETFL);
  if (flags >= 0) ::fcntl(fd, F_SETFL, flags | O_NONBLOCK);
}

// Blocks SIGPIPE in this thread while the child's standard input is written (a child that exits
// early turns the write into EPIPE instead of killing us); a SIGPIPE left pending is consumed.
class SigpipeBlock {
 public:
  SigpipeBlock() {
    sigemptyset(&pipe_);
    sigaddset(&pipe_, SIGPIPE);
    pthread_sigmask(SIG_BLOCK, &pipe_, &old_);
  }
  ~SigpipeBlock() {
    const timespec zero{0, 0};
    while (sigtimedwait(&pipe_, nullptr, &zero) > 0) {
    }
    pthread_sigmask(SIG_SETMASK, &old_, nullptr);
  }
  const sigset_t& old_mask() const { return old_; }

 private:
  sigset_t pipe_, old_;
};

std::string tail(const std::string& s, std::size_t n) {
  std::string t = s.size() > n ? "..." + s.substr(s.size() - n) : s;
  while (!t.empty() && (t.back() == '\n' || t.back() == ' ')) t.pop_back();
  return t;
}

}  // namespace

std::string gnuplot_program(const GnuplotOptions& opt) {
  if (!opt.program.empty()) return opt.program;
  if (const char* env = std::getenv("VALVEDIAG_GNUPLOT"); env != nullptr && *env != '\0')
    return env;
  return "gnuplot";
}

std::string gnuplot_quote(const std::string& text) {
  std::string q = "'";
  for (const char ch : text) {
    if (ch == '\'')
      q += "''";
    else if (static_cast<unsigned char>(ch) < 0x20 || ch == 0x7f)
      q += ' ';
    else
      q += ch;
  }
  return q + "'";
}

std::string gnuplot_run(const std::string& script, const GnuplotOptions& opt) {
  const std::string program = gnuplot_program(opt);
  Fd in_r, in_w, out_r, out_w, err_r, err_w;
  make_pipe(in_r, in_w);
  make_pipe(out_r, out_w);
  make_pipe(err_r, err_w);

  SigpipeBlock block;
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_adddup2(&fa, in_r.fd, 0);
  posix_spawn_file_actions_adddup2(&fa, out_w.fd, 1);
  posix_spawn_file_actions_adddup2(&fa, err_w.fd, 2);
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  // The child gets the caller's signal mask (not ours with SIGPIPE blocked) and default SIGPIPE.
  sigset_t def;
  sigemptyset(&def);
  sigaddset(&def, SIGPIPE);
  posix_spawnattr_setsigmask(&attr, &block.old_mask());
  posix_spawnattr_setsigdefault(&attr, &def);
  posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  std::vector<char> arg0(program.begin(), program.end());
  arg0.push_back('\0');
  char* argv[] = {arg0.data(), nullptr};
  pid_t pid = -1;
  const int rc = posix_spawnp(&pid, program.c_str(), &fa, &attr, argv, environ);
  posix_spawn_file_actions_destroy(&fa);
  posix_spawnattr_destroy(&attr);
  if (rc != 0) {
    throw GnuplotMissing(
        "cannot run gnuplot ('" + program + "': " + std::strerror(rc) +
        "): the report draws its plots with gnuplot; install it with 'apt-get install "
        "gnuplot-nox' (Debian/Ubuntu), or point VALVEDIAG_GNUPLOT at the gnuplot program");
  }
  in_r.reset();
  out_w.reset();
  err_w.reset();
  set_nonblocking(in_w.fd);
  set_nonblocking(out_r.fd);
  set_nonblocking(err_r.fd);

  std::string out, err;
  std::size_t written = 0;
  bool timed_out = false;
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(opt.timeout_s));
  if (script.empty()) in_w.reset();
  while (out_r.fd >= 0 || err_r.fd >= 0) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                          deadline - std::chrono::steady_clock::now())
                          .count();
    if (left <= 0) {
      timed_out = true;
      break;
    }
    pollfd fds[3];
    int n = 0;
    int i_in = -1, i_out = -1, i_err = -1;
    if (in_w.fd >= 0) fds[i_in = n++] = {in_w.fd, POLLOUT, 0};
    if (out_r.fd >= 0) fds[i_out = n++] = {out_r.fd, POLLIN, 0};
    if (err_r.fd >= 0) fds[i_err = n++] = {err_r.fd, POLLIN, 0};
    const int ready = ::poll(fds, static_cast<nfds_t>(n), static_cast<int>(left));
    if (ready < 0) {
      if (errno == EINTR) continue;
      break;
    }
    if (i_in >= 0 && fds[i_in].revents != 0) {
      const ssize_t w = ::write(in_w.fd, script.data() + written, script.size() - written);
      if (w > 0) written += static_cast<std::size_t>(w);
      if ((w < 0 && errno != EAGAIN && errno != EINTR) || written == script.size())
        in_w.reset();  // all sent (EOF ends gnuplot), or the child stopped reading
    }
    auto drain = [](Fd& fd, std::string& into) {
      char buf[65536];
      const ssize_t r = ::read(fd.fd, buf, sizeof buf);
      if (r > 0)
        into.append(buf, static_cast<std::size_t>(r));
      else if (r == 0 || (errno != EAGAIN && errno != EINTR))
        fd.reset();
    };
    if (i_out >= 0 && fds[i_out].revents != 0) drain(out_r, out);
    if (i_err >= 0 && fds[i_err].revents != 0) drain(err_r, err);
  }
  in_w.reset();
  if (timed_out) ::kill(pid, SIGKILL);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (timed_out)
    throw GnuplotError("gnuplot did not finish within " + std::to_string(opt.timeout_s) +
                       " s and was stopped");
  if (WIFSIGNALED(status))
    throw GnuplotError("gnuplot was killed by signal " + std::to_string(WTERMSIG(status)) +
                       (err.empty() ? "" : ": " + tail(err, 1500)));
  if (WIFEXITED(status) && WEXITSTATUS(status) == 127 && out.empty())
    throw GnuplotMissing("cannot run gnuplot ('" + program +
                         "'): install it with 'apt-get install gnuplot-nox' (Debian/Ubuntu), or "
                         "point VALVEDIAG_GNUPLOT at the gnuplot program");
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    throw GnuplotError("gnuplot failed (exit status " + std::to_string(WEXITSTATUS(status)) + ")" +
                       (err.empty() ? "" : ": " + tail(err, 1500)));
  return out;
}

}  // namespace valvediag
