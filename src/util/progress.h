// Progress of long loops (images of a calibration, views of a solve, runs of a study) for the
// user at the keyboard. Library code reports progress through a ProgressFn callback and never
// prints; the command decides how it is shown:
//   - stderr is a terminal: one bar redrawn in place ("\r"), ended by a newline;
//   - otherwise, with --verbose: one line per finished item (a log in a pipe or a file);
//   - otherwise: nothing (a pipe or a batch job's log stays clean).
#pragma once

#include <chrono>
#include <cstdio>
#include <functional>
#include <mutex>
#include <string>

namespace carmba {

// Called once per finished item with its name (may be empty). Thread-safe callers only.
using ProgressFn = std::function<void(const std::string& item)>;

enum class ProgressStyle { kNone, kBar, kLines };

// kBar on a terminal, else kLines with `verbose`, else kNone.
ProgressStyle ChooseProgressStyle(bool stderr_is_terminal, bool verbose);

// "H:MM:SS"-free short durations: "42s", "3m05s", "1h02m"; "?" for negative or absurd values.
std::string FormatDuration(double seconds);

// One line of the bar, without "\r" or "\n", e.g.
//   "calibrate [##########..........]  10/20 images  50%  3s, ETA 3s  img_0010.png"
// `width` is the number of cells of the bar; `item` is cut to 40 characters. ETA is "?" before
// the first item is done.
std::string FormatProgressBar(const std::string& label,
                              int done,
                              int total,
                              const std::string& unit,
                              double elapsed_s,
                              const std::string& item,
                              int width = 20);

// Shows the progress of `total` items of `unit` ("images", "views", "runs") on `out` (stderr) in
// the given style. Tick() is thread-safe; the bar is redrawn at most every 100 ms except for the
// last item. Finish() (or the destructor) ends the bar's line.
class Progress {
 public:
  Progress(std::string label, int total, std::string unit, ProgressStyle style, FILE* out = stderr);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;
  void Tick(const std::string& item = "");
  void Finish();
  // A ProgressFn that ticks this object (it must outlive the callback's use).
  ProgressFn Callback();

 private:
  std::string label_, unit_;
  int total_ = 0, done_ = 0;
  ProgressStyle style_;
  FILE* out_;
  std::mutex mutex_;
  std::chrono::steady_clock::time_point start_, last_draw_;
  bool drawn_ = false, finished_ = false;
};

}  // namespace carmba
