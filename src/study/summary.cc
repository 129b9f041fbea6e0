#include "study/summary.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <sstream>

#include "util/format.h"
#include "report/plots.h"

namespace carmba {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Nearest-rank percentile of sorted data.
double Percentile(const std::vector<double>& sorted, double q) {
  if (sorted.empty()) return kNaN;
  size_t rank = static_cast<size_t>(std::ceil(q * static_cast<double>(sorted.size())));
  rank = std::max<size_t>(rank, 1);
  return sorted[std::min(rank, sorted.size()) - 1];
}

double Median(std::vector<double> v) {
  if (v.empty()) return kNaN;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

struct Samples {
  std::vector<double> values;
  std::vector<double> sigmas;  // signed only; may be shorter when some runs had no sigma
};

MetricStats Stats(const std::string& kind, const std::string& name, const Samples& s) {
  MetricStats m;
  m.kind = kind;
  m.name = name;
  m.n = static_cast<int>(s.values.size());
  if (s.values.empty()) return m;
  const double n = static_cast<double>(s.values.size());
  double sum = 0, sum2 = 0;
  for (double v : s.values) {
    sum += v;
    sum2 += v * v;
  }
  m.mean = sum / n;
  m.rms = std::sqrt(sum2 / n);
  m.median = Median(s.values);
  std::vector<double> mag = s.values;
  for (double& v : mag) v = std::fabs(v);
  std::sort(mag.begin(), mag.end());
  m.p95 = Percentile(mag, 0.95);
  m.max = mag.back();
  if (kind == "signed") {
    double ss = 0;
    for (double v : s.values) ss += (v - m.mean) * (v - m.mean);
    m.emp_sigma = s.values.size() > 1 ? std::sqrt(ss / (n - 1)) : kNaN;
    if (!s.sigmas.empty() && s.sigmas.size() == s.values.size()) {
      double sig2 = 0;
      for (double v : s.sigmas) sig2 += v * v;
      m.has_sigma = true;
      m.pred_sigma = std::sqrt(sig2 / static_cast<double>(s.sigmas.size()));
      m.consistency = m.pred_sigma > 0 ? m.emp_sigma / m.pred_sigma : kNaN;
    }
  }
  return m;
}

bool IsNumber(const nlohmann::json& j) { return j.is_number() && std::isfinite(j.get<double>()); }

std::string Csv(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) {
    if (c == '"') q += '"';
    q += c == '\n' ? ' ' : c;
  }
  return q + "\"";
}

}  // namespace

const MetricStats* GroupSummary::Find(const std::string& kind, const std::string& name) const {
  for (const auto& m : metrics) {
    if (m.kind == kind && m.name == name) return &m;
  }
  return nullptr;
}

std::vector<GroupSummary> Summarize(std::vector<RunRecord> records) {
  SortRecords(&records);
  std::vector<GroupSummary> groups;
  std::map<std::string, size_t> group_of;
  // Per group: (kind, name) -> samples. std::map keeps names sorted.
  std::vector<std::map<std::pair<int, std::string>, Samples>> samples;
  std::vector<std::map<std::string, std::pair<double, int>>> budgets;
  for (const RunRecord& r : records) {
    const std::string gkey = r.problem + "|" + r.config + "|" + SweepPointLabel(r.sweep);
    auto it = group_of.find(gkey);
    if (it == group_of.end()) {
      GroupSummary g;
      g.problem = r.problem;
      g.config = r.config;
      g.sweep = r.sweep;
      g.first_index = r.index;
      it = group_of.emplace(gkey, groups.size()).first;
      groups.push_back(std::move(g));
      samples.emplace_back();
      budgets.emplace_back();
    }
    GroupSummary& g = groups[it->second];
    auto& gs = samples[it->second];
    ++g.runs;
    g.time_total_s += r.time_s;
    g.cpu_total_s += r.cpu_s;
    g.time_max_s = std::max(g.time_max_s, r.time_s);
    if (!r.ok) {
      ++g.failed;
      auto f = std::find_if(g.failures.begin(), g.failures.end(),
                            [&](const FailureGroup& x) { return x.error == r.error; });
      if (f == g.failures.end()) {
        g.failures.push_back(FailureGroup{r.error, 1, r.key});
      } else {
        ++f->count;
      }
      continue;
    }
    const nlohmann::json& res = r.result;
    if (!res.is_object()) continue;
    auto take = [&](const char* member, int kind) {
      if (!res.contains(member) || !res[member].is_object()) return;
      for (const auto& kv : res[member].items()) {
        if (IsNumber(kv.value())) gs[{kind, kv.key()}].values.push_back(kv.value().get<double>());
      }
    };
    take("errors", 0);
    take("signed_errors", 1);
    take("values", 2);
    if (res.contains("sigmas") && res["sigmas"].is_object() && res.contains("signed_errors")) {
      for (const auto& kv : res["sigmas"].items()) {
        if (IsNumber(kv.value()) && res["signed_errors"].contains(kv.key())) {
          gs[{1, kv.key()}].sigmas.push_back(kv.value().get<double>());
        }
      }
    }
    if (res.contains("converged") && res["converged"].is_boolean()) {
      gs[{2, "converged"}].values.push_back(res["converged"].get<bool>() ? 1.0 : 0.0);
    }
    if (res.contains("residuals_px") && res["residuals_px"].is_array()) {
      for (const auto& v : res["residuals_px"]) {
        if (IsNumber(v)) g.residuals.push_back(v.get<double>());
      }
    }
    if (res.contains("budget") && res["budget"].is_object()) {
      for (const auto& kv : res["budget"].items()) {
        if (!IsNumber(kv.value())) continue;
        auto& b = budgets[it->second][kv.key()];
        b.first += kv.value().get<double>();
        ++b.second;
      }
    }
  }
  static const char* const kKinds[] = {"error", "signed", "value"};
  for (size_t i = 0; i < groups.size(); ++i) {
    GroupSummary& g = groups[i];
    for (const auto& kv : samples[i]) {
      g.metrics.push_back(Stats(kKinds[kv.first.first], kv.first.second, kv.second));
    }
    for (const auto& kv : budgets[i]) {
      g.budget.emplace_back(kv.first, kv.second.first / kv.second.second);
    }
    g.time_mean_s = g.runs ? g.time_total_s / g.runs : 0;
  }
  std::sort(groups.begin(), groups.end(), [](const GroupSummary& a, const GroupSummary& b) {
    return a.first_index < b.first_index;
  });
  return groups;
}

std::vector<std::string> SweepNames(const std::vector<GroupSummary>& groups) {
  std::vector<std::string> names;
  for (const auto& g : groups) {
    for (const auto& kv : g.sweep) {
      if (std::find(names.begin(), names.end(), kv.first) == names.end()) {
        names.push_back(kv.first);
      }
    }
  }
  return names;
}

namespace {
std::vector<std::string> SweepCellList(const GroupSummary& g,
                                       const std::vector<std::string>& names) {
  std::vector<std::string> cells;
  for (const auto& name : names) {
    std::string cell;
    for (const auto& kv : g.sweep) {
      if (kv.first == name) cell = FormatNumber(kv.second);
    }
    cells.push_back(cell);
  }
  return cells;
}

std::string SweepCells(const GroupSummary& g, const std::vector<std::string>& names,
                       const char* sep) {
  std::string s;
  for (const auto& cell : SweepCellList(g, names)) s += cell + sep;
  return s;
}

// A table row: problem, config, the sweep cells, then `rest`.
std::vector<std::string> GroupRow(const GroupSummary& g,
                                  const std::vector<std::string>& sweeps,
                                  const std::vector<std::string>& rest) {
  std::vector<std::string> row = {g.problem, g.config};
  for (const auto& c : SweepCellList(g, sweeps)) row.push_back(c);
  row.insert(row.end(), rest.begin(), rest.end());
  return row;
}

std::vector<std::string> GroupHeader(const std::vector<std::string>& sweeps,
                                     const std::vector<std::string>& rest) {
  std::vector<std::string> h = {"problem", "config"};
  h.insert(h.end(), sweeps.begin(), sweeps.end());
  h.insert(h.end(), rest.begin(), rest.end());
  return h;
}

}  // namespace

std::string SummaryCsv(const std::vector<GroupSummary>& groups) {
  const std::vector<std::string> sweeps = SweepNames(groups);
  std::ostringstream out;
  out << "problem,config,";
  for (const auto& s : sweeps) out << Csv(s) << ",";
  out << "runs,failed,kind,metric,n,mean,median,rms,p95,max,pred_sigma,emp_sigma,consistency\n";
  for (const auto& g : groups) {
    const std::string prefix = Csv(g.problem) + "," + Csv(g.config) + "," +
                               SweepCells(g, sweeps, ",") + std::to_string(g.runs) + "," +
                               std::to_string(g.failed) + ",";
    if (g.metrics.empty()) out << prefix << "runs,-,0,,,,,,,,\n";
    for (const auto& m : g.metrics) {
      out << prefix << m.kind << "," << Csv(m.name) << "," << m.n << "," << FormatNumber(m.mean)
          << "," << FormatNumber(m.median) << "," << FormatNumber(m.rms) << ","
          << FormatNumber(m.p95) << "," << FormatNumber(m.max) << ",";
      if (m.kind == "signed") {
        if (m.has_sigma) out << FormatNumber(m.pred_sigma);
        out << "," << FormatNumber(m.emp_sigma) << ",";
        if (m.has_sigma) out << FormatNumber(m.consistency);
      } else {
        out << ",,";
      }
      out << "\n";
    }
  }
  return out.str();
}

std::string TimingCsv(const std::vector<GroupSummary>& groups) {
  const std::vector<std::string> sweeps = SweepNames(groups);
  std::ostringstream out;
  out << "problem,config,";
  for (const auto& s : sweeps) out << Csv(s) << ",";
  out << "runs,time_mean_s,time_max_s,time_total_s,cpu_total_s\n";
  for (const auto& g : groups) {
    out << Csv(g.problem) << "," << Csv(g.config) << "," << SweepCells(g, sweeps, ",") << g.runs
        << "," << FormatNumber(g.time_mean_s) << "," << FormatNumber(g.time_max_s) << ","
        << FormatNumber(g.time_total_s) << "," << FormatNumber(g.cpu_total_s) << "\n";
  }
  return out.str();
}

ReportDoc SummaryDoc(const nlohmann::json& info, const std::vector<GroupSummary>& groups) {
  const std::vector<std::string> sweeps = SweepNames(groups);
  int runs = 0, failed = 0;
  for (const auto& g : groups) {
    runs += g.runs;
    failed += g.failed;
  }
  ReportDoc d;
  d.Heading(1, "Study " + MarkdownCell(info.value("name", std::string("?"))));
  d.Paragraph("Runs recorded: " + std::to_string(runs) + " of " +
              std::to_string(info.value("runs_total", 0)) + ", failed: " + std::to_string(failed) +
              ". Study fingerprint `" + info.value("fingerprint", std::string("?")) + "`.");
  d.Paragraph("Errors are against the truth; each cell is median / p95 over the trials. "
              "Consistency = empirical spread / reported sigma (1 is honest, > 1 overconfident).");

  // Column sets: error metrics (median / p95) and value metrics (mean), union over groups.
  std::vector<std::string> errors, values;
  for (const auto& g : groups) {
    for (const auto& m : g.metrics) {
      if (m.kind == "signed") continue;
      auto& list = m.kind == "value" ? values : errors;
      if (std::find(list.begin(), list.end(), m.name) == list.end()) list.push_back(m.name);
    }
  }
  std::sort(errors.begin(), errors.end());
  std::sort(values.begin(), values.end());
  d.Heading(2, "Accuracy");
  std::vector<std::string> rest = {"runs", "failed"};
  rest.insert(rest.end(), errors.begin(), errors.end());
  for (const auto& v : values) rest.push_back(v + " (mean)");
  std::vector<std::vector<std::string>> rows;
  for (const auto& g : groups) {
    std::vector<std::string> cells = {std::to_string(g.runs), std::to_string(g.failed)};
    for (const auto& e : errors) {
      const MetricStats* m = g.Find("error", e);
      cells.push_back(m ? FormatNumber(m->median) + " / " + FormatNumber(m->p95) : "");
    }
    for (const auto& v : values) {
      const MetricStats* m = g.Find("value", v);
      cells.push_back(m ? FormatNumber(m->mean) : "");
    }
    rows.push_back(GroupRow(g, sweeps, cells));
  }
  d.Table(GroupHeader(sweeps, rest), rows);
  d.Figures({"error-vs-noise"});

  bool any_signed = false;
  for (const auto& g : groups) {
    for (const auto& m : g.metrics) any_signed |= m.kind == "signed";
  }
  if (any_signed) {
    d.Heading(2, "Reported sigma vs empirical spread");
    rows.clear();
    for (const auto& g : groups) {
      for (const auto& m : g.metrics) {
        if (m.kind != "signed") continue;
        rows.push_back(GroupRow(g, sweeps,
                                {m.name, std::to_string(m.n), FormatNumber(m.mean),
                                 FormatNumber(m.emp_sigma),
                                 m.has_sigma ? FormatNumber(m.pred_sigma) : "",
                                 m.has_sigma ? FormatNumber(m.consistency) : ""}));
      }
    }
    d.Table(GroupHeader(sweeps, {"parameter", "n", "bias", "empirical sigma", "reported sigma",
                                 "consistency"}),
            rows);
  }
  d.Figures({"sigma-consistency", "residual-histogram"});

  // The error budget per group: each quantity's predicted 1-sigma contribution per noise source
  // (the runs' "budget" entries "quantity.source", mean over the trials), and each source's share
  // of the variance.
  bool any_budget = false;
  for (const auto& g : groups) any_budget |= !g.budget.empty();
  if (any_budget) {
    d.Heading(2, "Error budget (predicted, mean over trials)");
    d.Paragraph("Each cell: the source's 1-sigma contribution, and its share of the variance.");
    rows.clear();
    for (const auto& g : groups) {
      std::vector<std::string> quantities;
      std::map<std::string, std::vector<std::pair<std::string, double>>> by_q;
      for (const auto& [entry, v] : g.budget) {
        const auto dot = entry.rfind('.');
        const std::string q = dot == std::string::npos ? entry : entry.substr(0, dot);
        if (!by_q.count(q)) quantities.push_back(q);
        by_q[q].emplace_back(dot == std::string::npos ? "total" : entry.substr(dot + 1), v);
      }
      for (const auto& q : quantities) {
        double total = 0;
        for (const auto& sv : by_q[q]) total += sv.second * sv.second;
        std::string cell;
        for (const auto& [src, v] : by_q[q]) {
          cell += (cell.empty() ? "" : " ") + src + " " + FormatNumber(v) + " (" +
                  Fmt("%.0f %%", total > 0 ? 100 * v * v / total : 0.0) + ");";
        }
        rows.push_back(GroupRow(g, sweeps, {q, cell}));
      }
    }
    d.Table(GroupHeader(sweeps, {"quantity", "source contributions"}), rows);
  }
  d.Figures({"error-budget"});

  d.Heading(2, "Failures");
  if (failed == 0) {
    d.Paragraph("None.");
  } else {
    // One line per (problem, config, message) over all sweep points.
    struct Row {
      std::string problem, config, error, first_key;
      int count;
    };
    std::vector<Row> failure_rows;
    for (const auto& g : groups) {
      for (const auto& f : g.failures) {
        auto it = std::find_if(failure_rows.begin(), failure_rows.end(), [&](const Row& r) {
          return r.problem == g.problem && r.config == g.config && r.error == f.error;
        });
        if (it == failure_rows.end()) {
          failure_rows.push_back(Row{g.problem, g.config, f.error, f.first_key, f.count});
        } else {
          it->count += f.count;
        }
      }
    }
    rows.clear();
    for (const auto& r : failure_rows) {
      rows.push_back({r.problem, r.config, std::to_string(r.count), "`" + r.first_key + "`",
                      r.error});
    }
    d.Table({"problem", "config", "runs failed", "first run", "error"}, rows);
  }

  return d;
}

void AddTimingSection(const nlohmann::json& info,
                      const std::vector<GroupSummary>& groups,
                      double wall_s,
                      int jobs,
                      ReportDoc* doc) {
  ReportDoc& d = *doc;
  const std::vector<std::string> sweeps = SweepNames(groups);
  d.Heading(2, "Timing");
  d.Paragraph("Wall-clock numbers vary between runs and machines; they are excluded from the "
              "reproducibility checks (timing.csv has them per group).");
  double total = 0, cpu = 0;
  for (const auto& g : groups) {
    total += g.time_total_s;
    cpu += g.cpu_total_s;
  }
  std::vector<std::string> items = {"runs from: shard " + info.value("shard", std::string("1/1")),
                                    "sum of the runs' own times: " + FormatNumber(total) +
                                        " s (CPU " + FormatNumber(cpu) + " s)"};
  if (wall_s > 0 && jobs > 0) {
    items.push_back("wall time of this invocation: " + FormatNumber(wall_s) + " s with " +
                    std::to_string(jobs) + " jobs");
  }
  d.List(items);
  std::vector<std::vector<std::string>> rows;
  for (const auto& g : groups) {
    rows.push_back(GroupRow(g, sweeps, {FormatNumber(g.time_mean_s), FormatNumber(g.time_max_s)}));
  }
  d.Table(GroupHeader(sweeps, {"mean s/run", "max s/run"}), rows);
}

nlohmann::json StudyPlotData(const std::vector<GroupSummary>& groups) {
  nlohmann::json problems = nlohmann::json::array(), configs = nlohmann::json::array(),
                 gj = nlohmann::json::array();
  auto add_unique = [](nlohmann::json* a, const std::string& x) {
    for (const auto& e : *a) {
      if (e == x) return;
    }
    a->push_back(x);
  };
  for (const auto& g : groups) {
    add_unique(&problems, g.problem);
    add_unique(&configs, g.config);
    nlohmann::json sweep = nlohmann::json::object();
    for (const auto& kv : g.sweep) sweep[kv.first] = kv.second;
    nlohmann::json metrics = nlohmann::json::array();
    for (const auto& m : g.metrics) {
      metrics.push_back({{"kind", m.kind},
                         {"name", m.name},
                         {"n", m.n},
                         {"median", JsonNumber(m.median)},
                         {"p95", JsonNumber(m.p95)},
                         {"has_sigma", m.has_sigma},
                         {"pred_sigma", JsonNumber(m.pred_sigma)},
                         {"emp_sigma", JsonNumber(m.emp_sigma)}});
    }
    nlohmann::json residuals = nlohmann::json::array();
    for (double r : g.residuals) {
      if (std::isfinite(r)) residuals.push_back(r);
    }
    nlohmann::json budget = nlohmann::json::array();
    for (const auto& [entry, v] : g.budget) {
      if (std::isfinite(v)) budget.push_back({entry, v});
    }
    gj.push_back({{"problem", g.problem},
                  {"config", g.config},
                  {"sweep", sweep},
                  {"metrics", metrics},
                  {"residuals", residuals},
                  {"budget", budget}});
  }
  return {{"kind", "study"},
          {"study", {{"problems", problems}, {"configs", configs}, {"groups", gj}}}};
}


}  // namespace carmba
