#include "ltmapper/pipeline/pipeline.hpp"

#include "test_util.hpp"

#include <gtest/gtest.h>

#include <filesystem>

namespace ltm {
namespace {

TEST(Markdown, TablesHeadingsListsAndEscaping) {
  const std::string html = pipeline::MarkdownToHtml(
      "# Title\n\n| a | b |\n|---|---|\n| 1 | <2> |\n\n- item `x`\n- two\n\nplain & **bold**\n");
  EXPECT_NE(html.find("<h2>Title</h2>"), std::string::npos) << html;
  EXPECT_NE(html.find("<tr><th>a</th><th>b</th></tr>"), std::string::npos) << html;
  EXPECT_NE(html.find("<tr><td>1</td><td>&lt;2&gt;</td></tr>"), std::string::npos) << html;
  EXPECT_EQ(html.find("---"), std::string::npos) << html;
  EXPECT_NE(html.find("<ul>\n<li>item <code>x</code></li>\n<li>two</li>\n</ul>"), std::string::npos) << html;
  EXPECT_NE(html.find("<p>plain &amp; <b>bold</b></p>"), std::string::npos) << html;
}

TEST(Report, WritesMarkdownAndHtmlWithRelativePictures) {
  test::TempDir dir;
  test::WriteText(dir / "eval/a.md", "## A\n\n| k | v |\n|---|---|\n| x | 1 |\n");
  test::WriteText(dir / "renders/p.png", "not really a png");
  pipeline::WriteReport(dir / "report", "T", {{dir / "eval/a.md", ""}, {dir / "renders/p.png", "cap"}});
  const std::string md = test::ReadText(dir / "report.md");
  const std::string html = test::ReadText(dir / "report.html");
  EXPECT_NE(md.find("# T"), std::string::npos);
  EXPECT_NE(md.find("| x | 1 |"), std::string::npos);
  EXPECT_NE(md.find("![cap](renders/p.png)"), std::string::npos) << md;
  EXPECT_NE(html.find("<img src=\"renders/p.png\""), std::string::npos) << html;
  EXPECT_NE(html.find("<td>x</td>"), std::string::npos);
}

TEST(Report, MissingOrWrongItemIsAnErrorAndWritesNothing) {
  test::TempDir dir;
  EXPECT_THROW(pipeline::WriteReport(dir / "r", "T", {{dir / "missing.md", ""}}), Error);
  test::WriteText(dir / "x.txt", "x");
  EXPECT_THROW(pipeline::WriteReport(dir / "r", "T", {{dir / "x.txt", ""}}), Error);
  EXPECT_FALSE(std::filesystem::exists(dir / "r.md"));
  EXPECT_FALSE(std::filesystem::exists(dir / "r.html"));
}

TEST(Run, NeedsTwoExistingSessions) {
  test::TempDir dir;
  pipeline::RunConfig cfg;
  EXPECT_THROW(pipeline::RunPipeline(cfg, {dir.str()}, dir / "out"), Error);
  try {
    pipeline::RunPipeline(cfg, {dir / "nope_a", dir / "nope_b"}, dir / "out");
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("nope_a"), std::string::npos) << e.what();
  }
}

TEST(Run, ResumeMarkerHoldsTheStageKey) {
  test::TempDir dir;
  const std::string marker = dir / "STAGE_DONE";
  EXPECT_FALSE(pipeline::StageDone(marker, "sessions: a b\nremovert: x\n"));  // no marker
  pipeline::MarkStageDone(marker, "sessions: a b\nremovert: x\n");
  EXPECT_TRUE(pipeline::StageDone(marker, "sessions: a b\nremovert: x\n"));
  EXPECT_FALSE(pipeline::StageDone(marker, "sessions: a b\nremovert: y\n"));  // a parameter changed
  EXPECT_FALSE(pipeline::StageDone(marker, "sessions: a b c\nremovert: x\n"));
  test::WriteText(marker, "ok\n");  // a marker written before markers held keys: rerun
  EXPECT_FALSE(pipeline::StageDone(marker, "sessions: a b\nremovert: x\n"));
}

TEST(Run, BadStageNameInConfigIsAnError) {
  pipeline::RunConfig cfg;
  cfg.from_stage = "everything";
  EXPECT_THROW(ValidateConfig(cfg), Error);
}

TEST(Cli, RunAndReportUsageErrorsExitNonZero) {
  std::string out;
  EXPECT_NE(test::RunCli("run --out /tmp/x", &out), 0);
  EXPECT_NE(test::RunCli("run --sessions /nonexistent_a /nonexistent_b --out /tmp/ltm_x", &out), 0);
  EXPECT_NE(out.find("nonexistent_a"), std::string::npos) << out;
  EXPECT_NE(test::RunCli("report --out /tmp/ltm_r --item /nonexistent.md", &out), 0);
}

// A read-only OUT is reported at once by every stage command, naming the directory (slam found
// out after 98 s of alignment; `run --from map` printed a raw "filesystem error").
TEST(Cli, ReadOnlyOutIsAnErrorBeforeAnyWork) {
  test::TempDir tmp;
  const std::string ro = tmp / "ro";
  for (const char* d : {"ro", "s0", "s1"}) std::filesystem::create_directories(tmp / d);
  std::filesystem::permissions(ro, std::filesystem::perms::owner_read | std::filesystem::perms::owner_exec);
  struct Restore {  // so TempDir can remove it
    std::string dir;
    ~Restore() { std::filesystem::permissions(dir, std::filesystem::perms::owner_all); }
  } restore{ro};
  if (access(ro.c_str(), W_OK) == 0) GTEST_SKIP() << "running as root: chmod does not make OUT read-only";
  const std::string sessions = " --sessions " + tmp / "s0" + " " + tmp / "s1";
  test::WriteText(tmp / "p.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n");
  for (const std::string& cmd : std::vector<std::string>{"slam" + sessions + " --out " + ro,
                                                         "run" + sessions + " --out " + ro + " --from map",
                                                         "removert --sessions " + tmp / "s0" + " --poses " + tmp / "p.txt" +
                                                             " --out " + ro}) {
    std::string out;
    EXPECT_NE(test::RunCli(cmd + " --quiet", &out), 0) << cmd;
    EXPECT_NE(out.find(ro + ": output directory is not writable"), std::string::npos) << cmd << "\n" << out;
    EXPECT_EQ(out.find("filesystem error"), std::string::npos) << cmd << "\n" << out;
  }
}

}  // namespace
}  // namespace ltm
