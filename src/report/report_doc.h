// One report, two formats: a ReportDoc is built once from a command's data (headings, paragraphs,
// lists, tables, warnings, places for plots) and written as report.md (Markdown()) and
// report.html (Html()), so the two always say the same thing.
//
// Text of paragraphs, list items and table cells is markdown inline text: `code` and **bold**
// are the only markup (HTML writes them as <code> and <strong>, everything else escaped). Table
// cells are escaped for markdown ('|') by the table itself.
//
// report.html is one self-contained file: the plots (report/plots.h) are PNGs embedded as
// data: URLs, no script or style is loaded from anywhere, no server is needed. A figure place
// (Figures()) shows the plots whose id starts with one of its prefixes; plots no place claimed
// go into a last section "More plots". Without plots (matplotlib missing) the page says so at the
// top. A script at the end of the page records, once the page has loaded, how many images were
// decoded (<body data-images-loaded=N data-images-total=M>) and any script error
// (data-js-error), so a headless browser's --dump-dom shows whether the page rendered.
#pragma once

#include <string>
#include <vector>

namespace carmba {

struct ReportPlot {
  std::string id;          // e.g. "residuals-per-view"
  std::string title;
  std::string caption;     // plain text
  std::string png_base64;  // the image
};

class ReportDoc {
 public:
  void Heading(int level, const std::string& text);
  void Paragraph(const std::string& text);
  void List(const std::vector<std::string>& items);
  // "> **Warning:** text" in markdown, a highlighted box in HTML.
  void Warning(const std::string& text);
  // A table; `header` may hold empty strings. Each row has header.size() cells.
  void Table(const std::vector<std::string>& header,
             const std::vector<std::vector<std::string>>& rows);
  // A preformatted block (``` in markdown, <pre> in HTML); `text` ends with a newline.
  void Code(const std::string& text);
  // Where the plots whose id starts with one of `id_prefixes` go (HTML only).
  void Figures(const std::vector<std::string>& id_prefixes);
  void Append(const ReportDoc& other);

  std::string Markdown() const;
  // `plots_note`, if not empty, is shown at the top (why there are no plots).
  std::string Html(const std::string& title,
                   const std::vector<ReportPlot>& plots,
                   const std::string& plots_note) const;

 private:
  enum class Kind { kHeading, kParagraph, kList, kWarning, kTable, kFigures, kCode };
  struct Block {
    Kind kind;
    int level = 0;
    std::string text;
    std::vector<std::string> items;             // list items, table header, figure prefixes
    std::vector<std::vector<std::string>> rows; // table rows
  };
  std::vector<Block> blocks_;
};

// Markdown inline text (`code`, **bold**) as HTML.
std::string InlineMarkdownToHtml(const std::string& text);

}  // namespace carmba
