#include "ltmapper/pipeline/pipeline.hpp"

#include "ltmapper/io/io.hpp"

#include <cmark-gfm-core-extensions.h>
#include <cmark-gfm.h>

#include <algorithm>

#include <filesystem>
#include <sstream>

namespace ltm::pipeline {
namespace fs = std::filesystem;

namespace {

std::string Escape(const std::string& s) {
  std::string out;
  out.reserve(s.size());
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

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// A parsed Markdown document (cmark-gfm with GitHub's tables), freed with it.
struct MarkdownDocument {
  cmark_parser* parser = nullptr;
  cmark_node* root = nullptr;
  explicit MarkdownDocument(const std::string& markdown) {
    cmark_gfm_core_extensions_ensure_registered();
    parser = cmark_parser_new(CMARK_OPT_DEFAULT);
    if (!parser) throw Error("markdown: cmark-gfm could not make a parser");
    cmark_syntax_extension* table = cmark_find_syntax_extension("table");
    if (!table) {
      cmark_parser_free(parser);
      throw Error("markdown: cmark-gfm has no table extension (libcmark-gfm-extensions)");
    }
    cmark_parser_attach_syntax_extension(parser, table);
    cmark_parser_feed(parser, markdown.data(), markdown.size());
    root = cmark_parser_finish(parser);
  }
  ~MarkdownDocument() {
    if (root) cmark_node_free(root);
    cmark_parser_free(parser);
  }
  MarkdownDocument(const MarkdownDocument&) = delete;
  MarkdownDocument& operator=(const MarkdownDocument&) = delete;
};

// Every heading one level down (the report's title is its only <h1>), at most <h6>.
void DemoteHeadings(cmark_node* root) {
  cmark_iter* it = cmark_iter_new(root);
  for (cmark_event_type ev; (ev = cmark_iter_next(it)) != CMARK_EVENT_DONE;) {
    cmark_node* node = cmark_iter_get_node(it);
    if (ev == CMARK_EVENT_ENTER && cmark_node_get_type(node) == CMARK_NODE_HEADING)
      cmark_node_set_heading_level(node, std::min(cmark_node_get_heading_level(node) + 1, 6));
  }
  cmark_iter_free(it);
}

}  // namespace

std::string MarkdownToHtml(const std::string& markdown) {
  const MarkdownDocument doc(markdown);
  DemoteHeadings(doc.root);
  char* html = cmark_render_html(doc.root, CMARK_OPT_DEFAULT, cmark_parser_get_syntax_extensions(doc.parser));
  std::string out(html ? html : "");
  cmark_get_default_mem_allocator()->free(html);
  return out;
}

void WriteReport(const std::string& out_base, const std::string& title, const std::vector<ReportItem>& items) {
  const fs::path base(out_base);
  const fs::path dir = base.has_parent_path() ? base.parent_path() : fs::path(".");
  std::ostringstream md, html;
  md << "# " << title << "\n\n";
  html << "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>" << Escape(title) << "</title>\n"
       << "<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}"
          "table{border-collapse:collapse;margin:.6em 0}td,th{border:1px solid #bbb;padding:3px 8px;"
          "text-align:right}th{background:#eee}figure{margin:1em 0}img{max-width:100%;border:1px solid #ccc}"
          "figcaption{font-size:90%;color:#555}code,pre{background:#f4f4f4}</style></head><body>\n"
       << "<h1>" << Escape(title) << "</h1>\n";
  for (const auto& item : items) {
    if (!fs::exists(item.path)) throw Error(item.path, 0, "report item not found");
    if (EndsWith(item.path, ".md")) {
      const std::string text = io::ReadFileText(item.path);
      md << text << (EndsWith(text, "\n") ? "\n" : "\n\n");
      html << "<section>\n" << MarkdownToHtml(text) << "</section>\n";
    } else if (EndsWith(item.path, ".png")) {
      const std::string rel = fs::relative(fs::absolute(item.path), fs::absolute(dir)).generic_string();
      const std::string caption = item.caption.empty() ? fs::path(item.path).filename().string() : item.caption;
      md << "![" << caption << "](" << rel << ")\n\n*" << caption << "*\n\n";
      html << "<figure><a href=\"" << Escape(rel) << "\"><img src=\"" << Escape(rel) << "\" alt=\""
           << Escape(caption) << "\"></a><figcaption>" << MarkdownToHtml(caption) << "</figcaption></figure>\n";
    } else {
      throw Error(item.path, 0, "report items must be .md or .png files");
    }
  }
  html << "</body></html>\n";
  io::WriteFileAtomic(out_base + ".md", [&](std::ostream& os) { os << md.str(); });
  io::WriteFileAtomic(out_base + ".html", [&](std::ostream& os) { os << html.str(); });
}

}  // namespace ltm::pipeline
