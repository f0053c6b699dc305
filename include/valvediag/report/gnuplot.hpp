// Runs gnuplot (the Debian package gnuplot-nox) as a child process: the script goes to its
// standard input, the SVG comes back on its standard output. No shell is involved: the program is
// started with posix_spawnp and an argument vector, and the data travel inside the script as
// inline data blocks, so nothing a user typed is ever interpreted by a shell.
#pragma once

#include <stdexcept>
#include <string>

namespace valvediag {

// gnuplot could not be started: not installed, not executable. The message says which package
// to install.
class GnuplotMissing : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// gnuplot started but failed: a script error, a crash, or it ran past its time limit.
class GnuplotError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct GnuplotOptions {
  // The program: a name looked up in PATH or a path. Empty: $VALVEDIAG_GNUPLOT when set, else
  // "gnuplot".
  std::string program;
  double timeout_s = 30.0;  // the child is killed (SIGKILL) after this long
};

// The program gnuplot_run would start for these options.
std::string gnuplot_program(const GnuplotOptions& opt);

// Runs the script and returns what gnuplot wrote to standard output. Throws GnuplotMissing when
// the program cannot be started, GnuplotError when it exits non-zero (its error output is in the
// message), is killed by a signal or runs past the time limit.
std::string gnuplot_run(const std::string& script, const GnuplotOptions& opt = {});

// A string as a gnuplot string literal in single quotes (where only '' needs escaping); control
// characters are replaced by spaces.
std::string gnuplot_quote(const std::string& text);

}  // namespace valvediag
