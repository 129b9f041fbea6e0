#include "study/report_html.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <tuple>
#include <sstream>

namespace carmba {
namespace {

const char* const kPalette[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e",
                                "#9467bd", "#8c564b", "#e377c2", "#17becf"};
constexpr int kPaletteSize = 8;

std::string Esc(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string F(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.2f", v);
  return buf;
}

std::string Tick(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.4g", v);
  return buf;
}

// 1-2-5 ticks covering [lo, hi].
std::vector<double> LinearTicks(double lo, double hi) {
  const double range = hi - lo;
  const double raw = range / 5;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  double step = mag;
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    step = m * mag;
    if (range / step <= 6) break;
  }
  std::vector<double> ticks;
  for (double t = std::ceil(lo / step) * step; t <= hi + 1e-9 * step; t += step) {
    ticks.push_back(std::fabs(t) < 1e-12 * step ? 0 : t);
  }
  return ticks;
}

// A 2-D plot written as SVG: axes with ticks, polylines, markers, bars, a legend.
class SvgPlot {
 public:
  SvgPlot(std::string kind, std::string title, std::string x_label, std::string y_label)
      : kind_(std::move(kind)),
        title_(std::move(title)),
        x_label_(std::move(x_label)),
        y_label_(std::move(y_label)) {}

  void SetRange(double x0, double x1, double y0, double y1, bool log_x, bool log_y) {
    log_x_ = log_x;
    log_y_ = log_y;
    x0_ = Tx(x0, log_x);
    x1_ = Tx(x1, log_x);
    y0_ = Tx(y0, log_y);
    y1_ = Tx(y1, log_y);
    if (!(x1_ > x0_)) {
      x0_ -= 0.5;
      x1_ += 0.5;
    }
    if (!(y1_ > y0_)) {
      y0_ -= 0.5;
      y1_ += 0.5;
    }
  }
  double Px(double x) const { return kLeft + (Tx(x, log_x_) - x0_) / (x1_ - x0_) * kPlotW; }
  double Py(double y) const {
    return kTop + kPlotH - (Tx(y, log_y_) - y0_) / (y1_ - y0_) * kPlotH;
  }

  void Line(const std::vector<std::pair<double, double>>& pts, const std::string& color,
            bool dashed = false) {
    if (pts.empty()) return;
    body_ << "<polyline fill=\"none\" stroke=\"" << color << "\" stroke-width=\"1.8\""
          << (dashed ? " stroke-dasharray=\"5,4\"" : "") << " points=\"";
    for (const auto& p : pts) body_ << F(Px(p.first)) << "," << F(Py(p.second)) << " ";
    body_ << "\"/>\n";
  }
  void Marker(double x, double y, const std::string& color, const std::string& tip) {
    body_ << "<circle cx=\"" << F(Px(x)) << "\" cy=\"" << F(Py(y)) << "\" r=\"3.5\" fill=\""
          << color << "\"><title>" << Esc(tip) << "</title></circle>\n";
  }
  // A bar in data coordinates: x from xa to xb, y from the axis bottom to y.
  void Bar(double xa, double xb, double y, const std::string& color, const std::string& tip) {
    const double top = Py(y), bottom = kTop + kPlotH;
    body_ << "<rect x=\"" << F(Px(xa)) << "\" y=\"" << F(std::min(top, bottom)) << "\" width=\""
          << F(std::max(0.5, Px(xb) - Px(xa))) << "\" height=\""
          << F(std::max(0.5, std::fabs(bottom - top))) << "\" fill=\"" << color << "\"><title>"
          << Esc(tip) << "</title></rect>\n";
  }
  void Legend(const std::string& name, const std::string& color) {
    legend_.emplace_back(name, color);
  }
  // Category labels under the x axis instead of numeric ticks.
  void Categories(const std::vector<std::pair<double, std::string>>& labels) {
    categories_ = labels;
  }

  std::string Svg() const {
    std::ostringstream s;
    const int height = kTop + kPlotH + 50 + 16 * static_cast<int>((legend_.size() + 2) / 3);
    s << "<svg class=\"plot\" data-plot=\"" << kind_ << "\" xmlns=\"http://www.w3.org/2000/svg\" "
      << "width=\"" << kWidth << "\" height=\"" << height << "\" viewBox=\"0 0 " << kWidth << " "
      << height << "\" font-family=\"sans-serif\" font-size=\"11\">\n";
    s << "<text x=\"" << kWidth / 2 << "\" y=\"16\" text-anchor=\"middle\" font-size=\"13\" "
      << "font-weight=\"bold\">" << Esc(title_) << "</text>\n";
    s << "<rect x=\"" << kLeft << "\" y=\"" << kTop << "\" width=\"" << kPlotW << "\" height=\""
      << kPlotH << "\" fill=\"#fafafa\" stroke=\"#333\"/>\n";
    // Y ticks.
    for (double t : AxisTicks(y0_, y1_, log_y_)) {
      const double py = kTop + kPlotH - (t - y0_) / (y1_ - y0_) * kPlotH;
      s << "<line x1=\"" << kLeft << "\" x2=\"" << kLeft + kPlotW << "\" y1=\"" << F(py)
        << "\" y2=\"" << F(py) << "\" stroke=\"#ddd\"/>"
        << "<text x=\"" << kLeft - 4 << "\" y=\"" << F(py + 4) << "\" text-anchor=\"end\">"
        << Tick(log_y_ ? std::pow(10.0, t) : t) << "</text>\n";
    }
    if (categories_.empty()) {
      for (double t : AxisTicks(x0_, x1_, log_x_)) {
        const double px = kLeft + (t - x0_) / (x1_ - x0_) * kPlotW;
        s << "<line x1=\"" << F(px) << "\" x2=\"" << F(px) << "\" y1=\"" << kTop << "\" y2=\""
          << kTop + kPlotH << "\" stroke=\"#ddd\"/>"
          << "<text x=\"" << F(px) << "\" y=\"" << kTop + kPlotH + 14
          << "\" text-anchor=\"middle\">" << Tick(log_x_ ? std::pow(10.0, t) : t) << "</text>\n";
      }
    } else {
      for (const auto& c : categories_) {
        s << "<text x=\"" << F(Px(c.first)) << "\" y=\"" << kTop + kPlotH + 14
          << "\" text-anchor=\"middle\">" << Esc(c.second) << "</text>\n";
      }
    }
    s << "<text x=\"" << kLeft + kPlotW / 2 << "\" y=\"" << kTop + kPlotH + 30
      << "\" text-anchor=\"middle\">" << Esc(x_label_) << "</text>\n";
    s << "<text transform=\"translate(14," << kTop + kPlotH / 2
      << ") rotate(-90)\" text-anchor=\"middle\">" << Esc(y_label_) << "</text>\n";
    s << "<g clip-path=\"none\">\n" << body_.str() << "</g>\n";
    for (size_t i = 0; i < legend_.size(); ++i) {
      const int lx = kLeft + static_cast<int>(i % 3) * (kPlotW / 3);
      const int ly = kTop + kPlotH + 46 + 16 * static_cast<int>(i / 3);
      s << "<rect x=\"" << lx << "\" y=\"" << ly - 9 << "\" width=\"12\" height=\"10\" fill=\""
        << legend_[i].second << "\"/><text x=\"" << lx + 16 << "\" y=\"" << ly << "\">"
        << Esc(legend_[i].first) << "</text>\n";
    }
    s << "</svg>\n";
    return s.str();
  }

 private:
  static constexpr int kWidth = 560, kLeft = 64, kTop = 28, kPlotW = 470, kPlotH = 260;
  static double Tx(double v, bool log) { return log ? std::log10(std::max(v, 1e-300)) : v; }
  static std::vector<double> AxisTicks(double lo, double hi, bool log) {
    if (!log) return LinearTicks(lo, hi);
    std::vector<double> t;
    for (double d = std::ceil(lo); d <= hi + 1e-9; d += 1) t.push_back(d);
    if (t.size() < 2) return LinearTicks(lo, hi);  // less than a decade: linear in log units
    return t;
  }

  std::string kind_, title_, x_label_, y_label_;
  bool log_x_ = false, log_y_ = false;
  double x0_ = 0, x1_ = 1, y0_ = 0, y1_ = 1;
  std::ostringstream body_;
  std::vector<std::pair<std::string, std::string>> legend_;
  std::vector<std::pair<double, std::string>> categories_;
};

std::string Color(size_t i) { return kPalette[i % kPaletteSize]; }

// Error metrics to plot, preferring the pose ones.
std::vector<std::string> PlotMetrics(const std::vector<GroupSummary>& groups) {
  std::set<std::string> all;
  for (const auto& g : groups) {
    for (const auto& m : g.metrics) {
      if (m.kind == "error") all.insert(m.name);
    }
  }
  std::vector<std::string> out;
  for (const char* pref : {"rotation_deg", "translation_mm", "tre_mm"}) {
    if (all.count(pref)) out.push_back(pref);
  }
  for (const auto& n : all) {
    if (out.size() >= 4) break;
    if (std::find(out.begin(), out.end(), n) == out.end()) out.push_back(n);
  }
  return out;
}

template <typename T>
void AddUnique(std::vector<T>* v, const T& x) {
  if (std::find(v->begin(), v->end(), x) == v->end()) v->push_back(x);
}

std::string ErrorVsNoise(const std::vector<GroupSummary>& groups,
                         const std::vector<std::string>& problems,
                         const std::vector<std::string>& configs,
                         std::vector<std::string>* notes) {
  std::string html;
  const std::vector<std::string> sweeps = SweepNames(groups);
  const std::vector<std::string> metrics = PlotMetrics(groups);
  for (const auto& var : sweeps) {
    // Distinct values of `var`, and the first value of every other variable.
    std::vector<double> values;
    std::map<std::string, double> baseline;
    for (const auto& g : groups) {
      for (const auto& kv : g.sweep) {
        if (kv.first == var) AddUnique(&values, kv.second);
        if (kv.first != var && !baseline.count(kv.first)) baseline[kv.first] = kv.second;
      }
    }
    if (values.size() < 2) continue;
    std::sort(values.begin(), values.end());
    for (const auto& problem : problems) {
      for (const auto& metric : metrics) {
        std::map<std::string, std::vector<std::pair<double, double>>> lines, p95;
        double lo = 0, hi = 0;
        bool any = false;
        for (const auto& g : groups) {
          if (g.problem != problem) continue;
          bool at_baseline = true;
          double x = 0;
          bool has_var = false;
          for (const auto& kv : g.sweep) {
            if (kv.first == var) {
              x = kv.second;
              has_var = true;
            } else if (baseline.count(kv.first) && baseline[kv.first] != kv.second) {
              at_baseline = false;
            }
          }
          const MetricStats* m = g.Find("error", metric);
          if (!has_var || !at_baseline || !m || m->n == 0) continue;
          lines[g.config].emplace_back(x, m->median);
          p95[g.config].emplace_back(x, m->p95);
          hi = any ? std::max(hi, m->p95) : m->p95;
          any = true;
        }
        if (!any) continue;
        std::string held;
        for (const auto& kv : baseline) held += ", " + kv.first + " = " + Tick(kv.second);
        SvgPlot plot("error-vs-noise", problem + ": " + metric + " vs " + var, var,
                     metric + " (median solid, p95 dashed)");
        plot.SetRange(values.front(), values.back(), lo, hi > 0 ? hi * 1.08 : 1, false, false);
        for (size_t c = 0; c < configs.size(); ++c) {
          if (!lines.count(configs[c])) continue;
          plot.Line(lines[configs[c]], Color(c));
          for (const auto& p : lines[configs[c]]) {
            plot.Marker(p.first, p.second, Color(c),
                        configs[c] + ": median " + Tick(p.second) + " at " + Tick(p.first));
          }
          plot.Line(p95[configs[c]], Color(c), /*dashed=*/true);
          plot.Legend(configs[c], Color(c));
        }
        html += "<figure>" + plot.Svg() + "<figcaption>Median (solid) and 95th percentile "
                "(dashed) of " + Esc(metric) + " against " + Esc(var) +
                (held.empty() ? std::string() : " (held: " + Esc(held.substr(2)) + ")") +
                ".</figcaption></figure>\n";
      }
    }
  }
  if (html.empty()) notes->push_back("No swept variable has two or more values: no error-vs-noise plot.");
  return html;
}

std::string SigmaConsistency(const std::vector<GroupSummary>& groups,
                             const std::vector<std::string>& configs,
                             std::vector<std::string>* notes) {
  double lo = 0, hi = 0;
  bool any = false;
  for (const auto& g : groups) {
    for (const auto& m : g.metrics) {
      if (m.kind != "signed" || !m.has_sigma || !(m.pred_sigma > 0) || !(m.emp_sigma > 0)) {
        continue;
      }
      const double a = std::min(m.pred_sigma, m.emp_sigma), b = std::max(m.pred_sigma, m.emp_sigma);
      lo = any ? std::min(lo, a) : a;
      hi = any ? std::max(hi, b) : b;
      any = true;
    }
  }
  if (!any) {
    notes->push_back("No run reported sigmas with two or more trials: no sigma-consistency plot.");
    return "";
  }
  lo /= 1.5;
  hi *= 1.5;
  SvgPlot plot("sigma-consistency", "Reported sigma vs empirical spread",
               "reported sigma (RMS over trials)", "empirical sigma (std over trials)");
  plot.SetRange(lo, hi, lo, hi, true, true);
  plot.Line({{lo, lo}, {hi, hi}}, "#888", /*dashed=*/true);
  for (size_t c = 0; c < configs.size(); ++c) {
    bool used = false;
    for (const auto& g : groups) {
      if (g.config != configs[c]) continue;
      for (const auto& m : g.metrics) {
        if (m.kind != "signed" || !m.has_sigma || !(m.pred_sigma > 0) || !(m.emp_sigma > 0)) {
          continue;
        }
        plot.Marker(m.pred_sigma, m.emp_sigma, Color(c),
                    g.problem + " " + g.config + " " + SweepPointLabel(g.sweep) + " " + m.name +
                        ": consistency " + Tick(m.consistency));
        used = true;
      }
    }
    if (used) plot.Legend(configs[c], Color(c));
  }
  return "<figure>" + plot.Svg() +
         "<figcaption>Each dot is one parameter of one problem x config x sweep point. On the "
         "dashed line y = x the reported uncertainty is honest; above it the solver is "
         "overconfident.</figcaption></figure>\n";
}

std::string ResidualHistograms(const std::vector<GroupSummary>& groups,
                               const std::vector<std::string>& problems,
                               const std::vector<std::string>& configs,
                               std::vector<std::string>* notes) {
  std::string html;
  constexpr int kBins = 40;
  for (const auto& problem : problems) {
    for (size_t c = 0; c < configs.size(); ++c) {
      std::vector<double> r;
      for (const auto& g : groups) {
        if (g.problem == problem && g.config == configs[c]) {
          r.insert(r.end(), g.residuals.begin(), g.residuals.end());
        }
      }
      if (r.size() < 2) continue;
      std::sort(r.begin(), r.end());
      // Range: the 0.5-99.5 % quantiles, symmetric, so a few outliers do not squash the plot.
      const double q_lo = r[r.size() / 200], q_hi = r[r.size() - 1 - r.size() / 200];
      double half = std::max(std::fabs(q_lo), std::fabs(q_hi));
      if (!(half > 0)) half = 1;
      std::vector<int> counts(kBins, 0);
      int outside = 0;
      for (double v : r) {
        const int b = static_cast<int>(std::floor((v + half) / (2 * half) * kBins));
        if (b < 0 || b >= kBins) {
          ++outside;
        } else {
          ++counts[b];
        }
      }
      const int top = *std::max_element(counts.begin(), counts.end());
      SvgPlot plot("residual-histogram", problem + " / " + configs[c] + ": residuals",
                   "residual (px)", "count");
      plot.SetRange(-half, half, 0, top * 1.1 + 1, false, false);
      for (int b = 0; b < kBins; ++b) {
        const double xa = -half + 2 * half * b / kBins, xb = -half + 2 * half * (b + 1) / kBins;
        plot.Bar(xa, xb, counts[b], Color(c), std::to_string(counts[b]) + " in [" + Tick(xa) +
                                                  ", " + Tick(xb) + ")");
      }
      html += "<figure>" + plot.Svg() + "<figcaption>" + std::to_string(r.size()) +
              " residuals pooled over the trials and sweep points" +
              (outside ? ", " + std::to_string(outside) + " outside the plotted range" : "") +
              ".</figcaption></figure>\n";
    }
  }
  if (html.empty()) notes->push_back("No run reported residuals: no residual histogram.");
  return html;
}

std::string ErrorBudget(const std::vector<GroupSummary>& groups,
                        const std::vector<std::string>& problems,
                        const std::vector<std::string>& configs) {
  std::string html;
  for (const auto& problem : problems) {
    // Entries "quantity.source" (e.g. v0_rotation_deg.pixel_noise), averaged over the sweep
    // points; one grouped bar chart per quantity with a bar per source in each config's slot.
    // Without a budget in the runs, the median errors (one "source") stand in.
    bool have_budget = false;
    for (const auto& g : groups) {
      if (g.problem == problem && !g.budget.empty()) have_budget = true;
    }
    std::vector<std::string> quantities, sources;
    // (config, quantity, source) -> (sum, count)
    std::map<std::tuple<std::string, std::string, std::string>, std::pair<double, int>> value;
    auto add = [&](const std::string& config, const std::string& entry, double v) {
      const auto dot = entry.rfind('.');
      const std::string q = dot == std::string::npos ? entry : entry.substr(0, dot);
      const std::string src = dot == std::string::npos
                                  ? std::string(have_budget ? "total" : "median error")
                                  : entry.substr(dot + 1);
      AddUnique(&quantities, q);
      AddUnique(&sources, src);
      auto& x = value[{config, q, src}];
      x.first += v;
      ++x.second;
    };
    for (const auto& g : groups) {
      if (g.problem != problem) continue;
      if (have_budget) {
        for (const auto& b : g.budget) add(g.config, b.first, b.second);
      } else {
        for (const auto& m : g.metrics) {
          if (m.kind == "error" && m.n > 0) add(g.config, m.name, m.median);
        }
      }
    }
    for (const auto& q : quantities) {
      double hi = 0;
      for (const auto& c : configs) {
        for (const auto& src : sources) {
          auto it = value.find({c, q, src});
          if (it != value.end()) hi = std::max(hi, it->second.first / it->second.second);
        }
      }
      if (!(hi > 0)) continue;
      SvgPlot plot("error-budget",
                   problem + ": " + (have_budget ? "predicted error budget of " : "median ") + q,
                   "config", have_budget ? q + " (1 sigma)" : q);
      plot.SetRange(0, static_cast<double>(configs.size()), 0, hi * 1.1, false, false);
      std::vector<std::pair<double, std::string>> labels;
      const double width = 0.7 / static_cast<double>(sources.size());
      for (size_t c = 0; c < configs.size(); ++c) {
        labels.emplace_back(c + 0.5, configs[c]);
        for (size_t k = 0; k < sources.size(); ++k) {
          auto it = value.find({configs[c], q, sources[k]});
          if (it == value.end()) continue;
          const double v = it->second.first / it->second.second;
          const double x0 = c + 0.15 + width * k;
          plot.Bar(x0, x0 + width, v, Color(have_budget ? k : c),
                   configs[c] + " " + sources[k] + ": " + Tick(v));
        }
      }
      if (have_budget) {
        for (size_t k = 0; k < sources.size(); ++k) plot.Legend(sources[k], Color(k));
      }
      plot.Categories(labels);
      html += "<figure>" + plot.Svg() + "<figcaption>" +
              (have_budget
                   ? "Predicted 1-sigma contribution of each noise source to " + Esc(q) +
                         " per config (the runs' \"budget\"; the squares add up to the reported "
                         "variance), averaged over trials and sweep points."
                   : "Median " + Esc(q) +
                         " per config, averaged over sweep points (the runs report no error "
                         "budget).") +
              "</figcaption></figure>\n";
    }
  }
  return html;
}

}  // namespace

std::string StudyReportHtml(const nlohmann::json& info, const std::vector<GroupSummary>& groups) {
  std::vector<std::string> problems, configs;
  int runs = 0, failed = 0;
  for (const auto& g : groups) {
    AddUnique(&problems, g.problem);
    AddUnique(&configs, g.config);
    runs += g.runs;
    failed += g.failed;
  }
  std::vector<std::string> notes;
  const std::string name = info.value("name", std::string("study"));
  std::ostringstream h;
  h << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>carmba study "
    << Esc(name) << "</title>\n<style>body{font-family:sans-serif;max-width:1200px;margin:1em auto;"
       "padding:0 1em;color:#222}figure{display:inline-block;margin:0.5em;vertical-align:top}"
       "figcaption{max-width:560px;font-size:0.85em;color:#555}h2{border-bottom:1px solid #ccc}"
       "</style></head>\n<body>\n";
  h << "<h1>Study " << Esc(name) << "</h1>\n<p>" << runs << " runs recorded of "
    << info.value("runs_total", 0) << ", " << failed << " failed; " << problems.size()
    << " problems, " << configs.size() << " configs. Fingerprint <code>"
    << Esc(info.value("fingerprint", std::string("?"))) << "</code>. Tables: summary.md, "
    << "summary.csv.</p>\n";
  h << "<h2>Error vs noise</h2>\n" << ErrorVsNoise(groups, problems, configs, &notes);
  h << "<h2>Predicted vs empirical sigma</h2>\n" << SigmaConsistency(groups, configs, &notes);
  h << "<h2>Residual histograms</h2>\n" << ResidualHistograms(groups, problems, configs, &notes);
  h << "<h2>Error budget</h2>\n" << ErrorBudget(groups, problems, configs);
  if (!notes.empty()) {
    h << "<h2>Notes</h2>\n<ul>\n";
    for (const auto& n : notes) h << "<li>" << Esc(n) << "</li>\n";
    h << "</ul>\n";
  }
  if (failed > 0) {
    h << "<h2>Failures</h2>\n<table border=\"1\" cellpadding=\"3\"><tr><th>problem</th>"
         "<th>config</th><th>sweep</th><th>runs</th><th>error</th></tr>\n";
    for (const auto& g : groups) {
      for (const auto& f : g.failures) {
        h << "<tr><td>" << Esc(g.problem) << "</td><td>" << Esc(g.config) << "</td><td>"
          << Esc(SweepPointLabel(g.sweep)) << "</td><td>" << f.count << "</td><td>"
          << Esc(f.error) << "</td></tr>\n";
      }
    }
    h << "</table>\n";
  }
  // Rendering self-check for headless browsers (see the header).
  h << "<script>\n(function(){\n  try {\n    var svgs = document.querySelectorAll('svg.plot');\n"
       "    var n = 0;\n    for (var i = 0; i < svgs.length; ++i) {\n"
       "      var b = svgs[i].getBBox();\n      if (b.width > 0 && b.height > 0) ++n;\n    }\n"
       "    document.body.setAttribute('data-plots-rendered', String(n));\n"
       "    document.body.setAttribute('data-plots-total', String(svgs.length));\n"
       "  } catch (e) {\n    document.body.setAttribute('data-js-error', String(e));\n  }\n"
       "})();\n</script>\n</body></html>\n";
  return h.str();
}

}  // namespace carmba
