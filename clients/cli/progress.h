// clients/cli/progress.h: a one-line progress bar on stderr (redrawn in place on a terminal,
// one line per 10 % otherwise so logs stay short). Not thread-safe.
#pragma once

#include <unistd.h>

#include <cstdio>
#include <string>

#include "common/core/timer.h"

namespace instascene::cli {

class ProgressBar {
 public:
  explicit ProgressBar(std::string label)
      : label_(std::move(label)), tty_(isatty(STDERR_FILENO) != 0) {}
  void Update(int done, int total) {
    const int percent = total > 0 ? 100 * done / total : 100;
    if (!tty_ && percent / 10 == last_decile_ && done != total) return;
    last_decile_ = percent / 10;
    const int width = 30, filled = width * percent / 100;
    const double elapsed = watch_.ElapsedSeconds();
    const double eta = done > 0 ? elapsed * (total - done) / done : 0.0;
    std::fprintf(stderr, "%s%s [%s%s] %d/%d %3d%% %.1fs eta %.1fs%s", tty_ ? "\r" : "",
                 label_.c_str(), std::string(filled, '#').c_str(),
                 std::string(width - filled, '.').c_str(), done, total, percent, elapsed, eta,
                 tty_ && done != total ? "" : "\n");
    std::fflush(stderr);
  }

 private:
  std::string label_;
  bool tty_;
  int last_decile_ = -1;
  Stopwatch watch_;
};

}  // namespace instascene::cli
