#include "report/report_doc.h"

#include <algorithm>
#include <set>
#include <sstream>

#include "util/format.h"

namespace carmba {

void ReportDoc::Heading(int level, const std::string& text) {
  blocks_.push_back({Kind::kHeading, level, text, {}, {}});
}
void ReportDoc::Paragraph(const std::string& text) {
  blocks_.push_back({Kind::kParagraph, 0, text, {}, {}});
}
void ReportDoc::List(const std::vector<std::string>& items) {
  if (items.empty()) return;
  blocks_.push_back({Kind::kList, 0, "", items, {}});
}
void ReportDoc::Warning(const std::string& text) {
  blocks_.push_back({Kind::kWarning, 0, text, {}, {}});
}
void ReportDoc::Table(const std::vector<std::string>& header,
                      const std::vector<std::vector<std::string>>& rows) {
  blocks_.push_back({Kind::kTable, 0, "", header, rows});
}
void ReportDoc::Code(const std::string& text) {
  blocks_.push_back({Kind::kCode, 0, text, {}, {}});
}
void ReportDoc::Figures(const std::vector<std::string>& id_prefixes) {
  blocks_.push_back({Kind::kFigures, 0, "", id_prefixes, {}});
}
void ReportDoc::Append(const ReportDoc& other) {
  blocks_.insert(blocks_.end(), other.blocks_.begin(), other.blocks_.end());
}

std::string ReportDoc::Markdown() const {
  std::ostringstream o;
  bool first = true;
  for (const Block& b : blocks_) {
    if (b.kind == Kind::kFigures) continue;
    if (!first) o << "\n";
    first = false;
    switch (b.kind) {
      case Kind::kHeading:
        o << std::string(b.level, '#') << " " << b.text << "\n";
        break;
      case Kind::kParagraph:
        o << b.text << "\n";
        break;
      case Kind::kList:
        for (const auto& i : b.items) o << "- " << i << "\n";
        break;
      case Kind::kWarning:
        o << "> **Warning:** " << b.text << "\n";
        break;
      case Kind::kTable: {
        o << "|";
        for (const auto& h : b.items) o << (h.empty() ? " " : " " + MarkdownCell(h) + " ") << "|";
        o << "\n|";
        for (size_t i = 0; i < b.items.size(); ++i) o << "---|";
        o << "\n";
        for (const auto& r : b.rows) {
          o << "|";
          for (const auto& c : r) o << (c.empty() ? " " : " " + MarkdownCell(c) + " ") << "|";
          o << "\n";
        }
        break;
      }
      case Kind::kCode:
        o << "```\n" << b.text << "```\n";
        break;
      case Kind::kFigures:
        break;
    }
  }
  return o.str();
}

std::string InlineMarkdownToHtml(const std::string& text) {
  std::string out;
  bool code = false, bold = false;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (c == '`') {
      out += code ? "</code>" : "<code>";
      code = !code;
    } else if (!code && c == '*' && i + 1 < text.size() && text[i + 1] == '*') {
      out += bold ? "</strong>" : "<strong>";
      bold = !bold;
      ++i;
    } else {
      out += HtmlEscape(std::string(1, c));
    }
  }
  if (code) out += "</code>";
  if (bold) out += "</strong>";
  return out;
}

namespace {

void WriteFigure(const ReportPlot& p, std::ostringstream& o) {
  o << "<figure class=\"plot\" data-plot=\"" << HtmlEscape(p.id) << "\"><img alt=\""
    << HtmlEscape(p.title) << "\" src=\"data:image/png;base64," << p.png_base64
    << "\"><figcaption>" << HtmlEscape(p.caption) << "</figcaption></figure>\n";
}

bool StartsWith(const std::string& s, const std::string& prefix) {
  return s.compare(0, prefix.size(), prefix) == 0;
}

}  // namespace

std::string ReportDoc::Html(const std::string& title,
                            const std::vector<ReportPlot>& plots,
                            const std::string& plots_note) const {
  std::ostringstream o;
  o << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>"
    << HtmlEscape(title)
    << "</title>\n<style>\n"
       "body{font-family:sans-serif;max-width:1250px;margin:1em auto;padding:0 1em;color:#222;"
       "line-height:1.4}\n"
       "h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;margin-top:1.6em}\n"
       "table{border-collapse:collapse;margin:0.5em 0;font-size:0.9em}\n"
       "th,td{border:1px solid #ccc;padding:2px 8px;text-align:left;vertical-align:top}\n"
       "th{background:#f0f0f0}tr:nth-child(even) td{background:#fafafa}\n"
       "code{background:#f3f3f3;padding:0 3px;font-size:0.95em}"
       "pre{background:#f3f3f3;padding:0.5em}\n"
       ".warning{border-left:4px solid #d62728;background:#fff3f3;padding:0.4em 0.8em}\n"
       ".note{border-left:4px solid #ff7f0e;background:#fff8ef;padding:0.4em 0.8em}\n"
       "figure.plot{display:inline-block;margin:0.5em;vertical-align:top;max-width:100%}\n"
       "figure.plot img{max-width:100%;height:auto}\n"
       "figcaption{max-width:620px;font-size:0.85em;color:#555}\n"
       "</style></head>\n<body>\n";
  if (!plots_note.empty()) {
    o << "<p class=\"note\" id=\"plots-unavailable\">" << HtmlEscape(plots_note) << "</p>\n";
  }
  std::set<size_t> placed;
  for (const Block& b : blocks_) {
    switch (b.kind) {
      case Kind::kHeading:
        o << "<h" << b.level << ">" << InlineMarkdownToHtml(b.text) << "</h" << b.level << ">\n";
        break;
      case Kind::kParagraph:
        o << "<p>" << InlineMarkdownToHtml(b.text) << "</p>\n";
        break;
      case Kind::kList:
        o << "<ul>\n";
        for (const auto& i : b.items) o << "<li>" << InlineMarkdownToHtml(i) << "</li>\n";
        o << "</ul>\n";
        break;
      case Kind::kWarning:
        o << "<p class=\"warning\"><strong>Warning:</strong> " << InlineMarkdownToHtml(b.text)
          << "</p>\n";
        break;
      case Kind::kTable:
        o << "<table>\n";
        // A header of empty cells (a key-value table) is markdown's necessity, not content.
        if (std::any_of(b.items.begin(), b.items.end(), [](const std::string& h) {
              return !h.empty();
            })) {
          o << "<tr>";
          for (const auto& h : b.items) o << "<th>" << InlineMarkdownToHtml(h) << "</th>";
          o << "</tr>\n";
        }
        for (const auto& r : b.rows) {
          o << "<tr>";
          for (const auto& c : r) o << "<td>" << InlineMarkdownToHtml(c) << "</td>";
          o << "</tr>\n";
        }
        o << "</table>\n";
        break;
      case Kind::kCode:
        o << "<pre>" << HtmlEscape(b.text) << "</pre>\n";
        break;
      case Kind::kFigures:
        for (size_t k = 0; k < plots.size(); ++k) {
          if (placed.count(k)) continue;
          for (const auto& prefix : b.items) {
            if (StartsWith(plots[k].id, prefix)) {
              WriteFigure(plots[k], o);
              placed.insert(k);
              break;
            }
          }
        }
        break;
    }
  }
  if (placed.size() < plots.size()) {
    o << "<h2>More plots</h2>\n";
    for (size_t k = 0; k < plots.size(); ++k) {
      if (!placed.count(k)) WriteFigure(plots[k], o);
    }
  }
  o << "<script>\nwindow.addEventListener('error', function(e) {\n"
       "  document.body.setAttribute('data-js-error', String(e.message));\n});\n"
       "window.addEventListener('load', function() {\n"
       "  var imgs = document.images, n = 0;\n"
       "  for (var i = 0; i < imgs.length; ++i) {\n"
       "    if (imgs[i].complete && imgs[i].naturalWidth > 0) ++n;\n  }\n"
       "  document.body.setAttribute('data-images-loaded', String(n));\n"
       "  document.body.setAttribute('data-images-total', String(imgs.length));\n"
       "});\n</script>\n</body></html>\n";
  return o.str();
}

}  // namespace carmba
