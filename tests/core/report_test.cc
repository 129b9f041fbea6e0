// The report layer: one document written as markdown and as HTML (report/report_doc.h), the
// embedded plot script, the plot runner's failure handling and the intrinsics-only projection
// uncertainty (report/plots.h).
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "camera/camera.h"
#include "util/format.h"
#include "report/plots.h"
#include "report/report_doc.h"
#include "util/file_util.h"

namespace carmba {
namespace {

ReportDoc SampleDoc() {
  ReportDoc d;
  d.Heading(1, "Title");
  d.Paragraph("Some `code` and **bold** <b>not html</b> & more.");
  d.List({"one", "two"});
  d.Warning("careful.");
  d.Table({"a", ""}, {{"x|y", "1.5"}, {"", "2"}});
  d.Figures({"resid"});
  d.Heading(2, "Next");
  return d;
}

TEST(ReportDocTest, Markdown) {
  EXPECT_EQ(SampleDoc().Markdown(),
            "# Title\n\nSome `code` and **bold** <b>not html</b> & more.\n\n- one\n- two\n\n"
            "> **Warning:** careful.\n\n| a | |\n|---|---|\n| x\\|y | 1.5 |\n| | 2 |\n\n## Next\n");
}

TEST(ReportDocTest, HtmlHasTheSameContentEscapedWithFiguresInPlace) {
  const std::vector<ReportPlot> plots = {{"other", "Other", "cap <2>", "BBBB"},
                                         {"residuals", "Residuals", "cap 1", "AAAA"}};
  const std::string html = SampleDoc().Html("T <1>", plots, "");
  EXPECT_NE(html.find("<title>T &lt;1&gt;</title>"), std::string::npos);
  EXPECT_NE(html.find("<p>Some <code>code</code> and <strong>bold</strong> &lt;b&gt;not "
                      "html&lt;/b&gt; &amp; more.</p>"),
            std::string::npos);
  EXPECT_NE(html.find("<li>two</li>"), std::string::npos);
  EXPECT_NE(html.find("<p class=\"warning\"><strong>Warning:</strong> careful.</p>"),
            std::string::npos);
  EXPECT_NE(html.find("<tr><td>x|y</td><td>1.5</td></tr>"), std::string::npos);
  // The figure whose id matches the place sits between the table and the next heading; the
  // other goes to "More plots" at the end.
  const auto table = html.find("</table>"), next = html.find("<h2>Next</h2>");
  const auto resid = html.find("data-plot=\"residuals\""), other = html.find("data-plot=\"other\"");
  const auto more = html.find("<h2>More plots</h2>");
  ASSERT_NE(resid, std::string::npos);
  ASSERT_NE(other, std::string::npos);
  ASSERT_NE(more, std::string::npos);
  EXPECT_LT(table, resid);
  EXPECT_LT(resid, next);
  EXPECT_LT(more, other);
  EXPECT_NE(html.find("src=\"data:image/png;base64,AAAA\""), std::string::npos);
  EXPECT_NE(html.find("<figcaption>cap &lt;2&gt;</figcaption>"), std::string::npos);
  EXPECT_EQ(html.find("plots-unavailable"), std::string::npos);
  // With a note and no plots: the note at the top, no figure, no "More plots".
  const std::string bare = SampleDoc().Html("T", {}, "Plots unavailable: why");
  EXPECT_NE(bare.find("id=\"plots-unavailable\">Plots unavailable: why</p>"), std::string::npos);
  EXPECT_EQ(bare.find("<figure"), std::string::npos);
  EXPECT_EQ(bare.find("More plots"), std::string::npos);
}

TEST(ReportFormatTest, NumbersAndJson) {
  EXPECT_EQ(Fmt("%.2f", 1.234), "1.23");
  EXPECT_EQ(Fmt("%.2f", std::nan("")), "n/a");
  EXPECT_EQ(Fixed(2.0, 1), "2.0");
  EXPECT_EQ(FmtRoundTrip(0.1), "0.10000000000000001");
  EXPECT_EQ(FormatNumber(-0.0), "0");
  EXPECT_EQ(FormatNumber(std::nan("")), "nan");
  EXPECT_TRUE(JsonNumber(INFINITY).is_null());
  EXPECT_EQ(JsonRows(Eigen::Matrix2d::Identity()).dump(), "[[1.0,0.0],[0.0,1.0]]");
}

TEST(ReportPlotsTest, EmbeddedScriptMatchesFile) {
  auto text = ReadFile(std::string(CARMBA_SOURCE_DIR) + "/scripts/report_plots.py");
  ASSERT_TRUE(text.ok());
  EXPECT_EQ(*text, std::string(ReportPlotsScript()))
      << "re-run cmake: the embedded script is generated from scripts/report_plots.py";
}

TEST(ReportPlotsTest, MissingPythonGivesNoPlotsAndAReason) {
  PlotOptions o;
  o.python = "/nonexistent/python3";
  const PlotSet s = MakePlots({{"kind", "pose"}}, o);
  EXPECT_TRUE(s.plots.empty());
  EXPECT_EQ(s.unavailable, "/nonexistent/python3 cannot be run (exit 127)");
  const ReportFiles f = RenderReport(SampleDoc(), "T", {{"kind", "pose"}}, o);
  EXPECT_EQ(f.markdown, SampleDoc().Markdown());
  EXPECT_EQ(f.warning, "report.html has no plots: /nonexistent/python3 cannot be run (exit 127)");
  EXPECT_NE(f.html.find("Plots unavailable: /nonexistent/python3 cannot be run"),
            std::string::npos);
}

// Without distortion, q = f X/Z + c with the point fixed in the camera frame: dq_u/dfx = x,
// dq_u/dcx = 1, so with a diagonal covariance Var(q_u) = x^2 Var(fx) + Var(cx).
TEST(ReportPlotsTest, IntrinsicsProjectionUncertaintyIsHandWorked) {
  constexpr double kTol = 1e-9;  // closed form vs Jet derivatives: rounding only
  const double intr[kNumIntrinsics] = {1000, 1000, 200, 150, 0, 0, 0, 0, 0};
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(kNumIntrinsics, kNumIntrinsics);
  C(0, 0) = 4;     // fx
  C(1, 1) = 9;     // fy
  C(2, 2) = 1;     // cx
  C(3, 3) = 0.25;  // cy
  // A 3 x 3 grid over a 401 x 301 image: pixel (200, 150) is the centre, (400, 150) the right.
  const nlohmann::json j = IntrinsicsProjectionUncertainty("c", intr, C, 401, 301, 700, 3, 3);
  ASSERT_EQ(j["worst_px"].size(), 9u);
  EXPECT_NEAR(j["worst_px"][4].get<double>(), 1.0, kTol);  // max(sigma_cx, sigma_cy)
  const double x = 0.2;  // (400 - 200) / 1000
  EXPECT_NEAR(j["worst_px"][5].get<double>(), std::sqrt(x * x * 4 + 1), kTol);
  const double y = 0.15;  // (300 - 150) / 1000; corner (400, 300): u and v independent
  EXPECT_NEAR(j["worst_px"][8].get<double>(),
              std::max(std::sqrt(x * x * 4 + 1), std::sqrt(y * y * 9 + 0.25)), kTol);
}

}  // namespace
}  // namespace carmba
