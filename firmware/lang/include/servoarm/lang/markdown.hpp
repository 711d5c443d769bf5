// SPDX-License-Identifier: Apache-2.0
#pragma once
// The reference sections of the manual that are generated from a table (the console's command
// table, the configuration's key table): how a table cell is escaped, and how a page's section
// is compared with what the generator makes now. Set-up and tool code (allocates).

#include <string>
#include <string_view>

namespace servoarm::fw {

/// `s` as one GitHub-flavoured Markdown table cell: every '|' not already escaped becomes "\|"
/// (in code spans too).
std::string md_cell(std::string_view s);

/// What a generated section of a page looks like against its generator.
struct GeneratedSection {
  const char* begin_prefix;  ///< the BEGIN marker line starts with this ("<!-- BEGIN console-reference")
  const char* end_line;      ///< the END marker line, whole ("<!-- END console-reference -->")
  const char* title;         ///< the diff's first line ("docs/console.md differs from armctl console --reference")
  const char* how;           ///< how to regenerate, the diff's last line
};

/// "" when `page`'s lines from the BEGIN marker to the END marker equal `generated` line for
/// line; else one line saying the markers are missing, or a line diff (longest common
/// subsequence, at most 40 lines: "- line N: <page>" and "+ <generated>"), then `s.how`.
std::string generated_section_mismatch(const std::string& page, const std::string& generated, const GeneratedSection& s);

}  // namespace servoarm::fw
