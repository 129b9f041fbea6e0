#include "util/progress.h"

#include <algorithm>
#include <cmath>

namespace carmba {

ProgressStyle ChooseProgressStyle(bool stderr_is_terminal, bool verbose) {
  if (stderr_is_terminal) return ProgressStyle::kBar;
  return verbose ? ProgressStyle::kLines : ProgressStyle::kNone;
}

std::string FormatDuration(double s) {
  if (!(s >= 0) || s > 1e7) return "?";
  char buf[32];
  const int total = static_cast<int>(s + 0.5);
  if (total >= 3600) {
    std::snprintf(buf, sizeof(buf), "%dh%02dm", total / 3600, (total / 60) % 60);
  } else if (total >= 60) {
    std::snprintf(buf, sizeof(buf), "%dm%02ds", total / 60, total % 60);
  } else {
    std::snprintf(buf, sizeof(buf), "%ds", total);
  }
  return buf;
}

std::string FormatProgressBar(const std::string& label,
                              int done,
                              int total,
                              const std::string& unit,
                              double elapsed_s,
                              const std::string& item,
                              int width) {
  const double fraction = total > 0 ? std::clamp(static_cast<double>(done) / total, 0.0, 1.0) : 1.0;
  const int filled = static_cast<int>(std::floor(fraction * width + 1e-9));
  std::string bar(static_cast<size_t>(filled), '#');
  bar += std::string(static_cast<size_t>(width - filled), '.');
  const std::string eta =
      done > 0 ? FormatDuration(elapsed_s / done * std::max(0, total - done)) : "?";
  const std::string count_width = std::to_string(total);
  char head[128];
  std::snprintf(head, sizeof(head), "%*d/%d %s %3d%%  %s, ETA %s",
                static_cast<int>(count_width.size()), done, total, unit.c_str(),
                static_cast<int>(std::floor(100 * fraction + 1e-9)),
                FormatDuration(elapsed_s).c_str(), eta.c_str());
  std::string line = label + " [" + bar + "] " + head;
  if (!item.empty()) {
    line += "  ";
    line += item.size() > 40 ? "..." + item.substr(item.size() - 37) : item;
  }
  return line;
}

Progress::Progress(std::string label, int total, std::string unit, ProgressStyle style, FILE* out)
    : label_(std::move(label)),
      unit_(std::move(unit)),
      total_(total),
      style_(style),
      out_(out),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_ - std::chrono::seconds(1)) {}

Progress::~Progress() { Finish(); }

void Progress::Tick(const std::string& item) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++done_;
  if (style_ == ProgressStyle::kNone || finished_) return;
  const auto now = std::chrono::steady_clock::now();
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  if (style_ == ProgressStyle::kLines) {
    std::fprintf(out_, "%s: %d/%d %s done (%s)%s%s\n", label_.c_str(), done_, total_,
                 unit_.c_str(), FormatDuration(elapsed).c_str(), item.empty() ? "" : ": ",
                 item.c_str());
    std::fflush(out_);
    return;
  }
  if (done_ < total_ && now - last_draw_ < std::chrono::milliseconds(100)) return;
  last_draw_ = now;
  // Pad with spaces so that a shorter line fully covers the previous one.
  std::fprintf(out_, "\r%-100s",
               FormatProgressBar(label_, done_, total_, unit_, elapsed, item).c_str());
  std::fflush(out_);
  drawn_ = true;
}

void Progress::Finish() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (finished_) return;
  finished_ = true;
  if (style_ == ProgressStyle::kBar && drawn_) {
    std::fprintf(out_, "\n");
    std::fflush(out_);
  }
}

ProgressFn Progress::Callback() {
  return [this](const std::string& item) { Tick(item); };
}

}  // namespace carmba
