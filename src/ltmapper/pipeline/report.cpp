#include "ltmapper/pipeline/pipeline.hpp"

#include "ltmapper/io/io.hpp"

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

// Escaped text with `code` spans and **bold**.
std::string Inline(const std::string& s) {
  std::string out;
  bool code = false, bold = false;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '`') {
      out += code ? "</code>" : "<code>";
      code = !code;
    } else if (!code && s.compare(i, 2, "**") == 0) {
      out += bold ? "</b>" : "<b>";
      bold = !bold;
      ++i;
    } else {
      out += Escape(std::string(1, s[i]));
    }
  }
  if (code) out += "</code>";
  if (bold) out += "</b>";
  return out;
}

std::vector<std::string> Cells(const std::string& line) {
  std::vector<std::string> cells;
  std::string t = line;
  const auto a = t.find_first_not_of(" \t");
  const auto b = t.find_last_not_of(" \t");
  t = t.substr(a, b - a + 1);
  if (!t.empty() && t.front() == '|') t.erase(0, 1);
  if (!t.empty() && t.back() == '|') t.pop_back();
  std::stringstream ss(t);
  std::string cell;
  while (std::getline(ss, cell, '|')) {
    const auto x = cell.find_first_not_of(' ');
    const auto y = cell.find_last_not_of(' ');
    cells.push_back(x == std::string::npos ? "" : cell.substr(x, y - x + 1));
  }
  return cells;
}

bool IsSeparatorRow(const std::string& line) {
  return line.find_first_not_of("|-: \t") == std::string::npos && line.find('-') != std::string::npos;
}

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

}  // namespace

std::string MarkdownToHtml(const std::string& markdown) {
  std::istringstream in(markdown);
  std::ostringstream out;
  std::string line;
  std::vector<std::string> lines;
  while (std::getline(in, line)) lines.push_back(line);
  bool in_list = false, in_pre = false;
  std::string para;
  auto flush_para = [&] {
    if (!para.empty()) out << "<p>" << Inline(para) << "</p>\n";
    para.clear();
  };
  auto close_list = [&] {
    if (in_list) out << "</ul>\n";
    in_list = false;
  };
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const std::string& l = lines[i];
    if (l.rfind("```", 0) == 0) {
      flush_para();
      close_list();
      out << (in_pre ? "</pre>\n" : "<pre>");
      in_pre = !in_pre;
      continue;
    }
    if (in_pre) {
      out << Escape(l) << "\n";
      continue;
    }
    const auto first = l.find_first_not_of(" \t");
    if (first == std::string::npos) {
      flush_para();
      close_list();
      continue;
    }
    if (l[first] == '#') {
      flush_para();
      close_list();
      std::size_t level = 0;
      while (first + level < l.size() && l[first + level] == '#') ++level;
      level = std::min<std::size_t>(level + 1, 6);  // the report title is the only <h1>
      out << "<h" << level << ">" << Inline(l.substr(l.find_first_not_of("# ", first))) << "</h" << level
          << ">\n";
      continue;
    }
    if (l[first] == '|') {
      flush_para();
      close_list();
      out << "<table>\n";
      bool header = i + 1 < lines.size() && IsSeparatorRow(lines[i + 1]);
      for (; i < lines.size(); ++i) {
        const auto f = lines[i].find_first_not_of(" \t");
        if (f == std::string::npos || lines[i][f] != '|') break;
        if (IsSeparatorRow(lines[i])) continue;
        out << "<tr>";
        for (const auto& c : Cells(lines[i])) out << (header ? "<th>" : "<td>") << Inline(c) << (header ? "</th>" : "</td>");
        out << "</tr>\n";
        header = false;
      }
      --i;
      out << "</table>\n";
      continue;
    }
    if ((l[first] == '-' || l[first] == '*') && first + 1 < l.size() && l[first + 1] == ' ') {
      flush_para();
      if (!in_list) out << "<ul>\n";
      in_list = true;
      out << "<li>" << Inline(l.substr(first + 2)) << "</li>\n";
      continue;
    }
    close_list();
    para += (para.empty() ? "" : " ") + l.substr(first);
  }
  flush_para();
  close_list();
  if (in_pre) out << "</pre>\n";
  return out.str();
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
           << Escape(caption) << "\"></a><figcaption>" << Inline(caption) << "</figcaption></figure>\n";
    } else {
      throw Error(item.path, 0, "report items must be .md or .png files");
    }
  }
  html << "</body></html>\n";
  io::WriteFileAtomic(out_base + ".md", [&](std::ostream& os) { os << md.str(); });
  io::WriteFileAtomic(out_base + ".html", [&](std::ostream& os) { os << html.str(); });
}

}  // namespace ltm::pipeline
