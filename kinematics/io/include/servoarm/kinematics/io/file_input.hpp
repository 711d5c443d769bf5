// SPDX-License-Identifier: Apache-2.0
#pragma once
// Reading the files the firmware reads (robot descriptions, armfw's configuration, and
// the points/frames/program files to come): one place for the size cap, the file-type
// checks and the TOML parser, so every loader refuses bad input the same way.
//
// Set-up code, never on the control path: it allocates and does I/O. Exception-free
// (kinematics is built -fno-exceptions): errors are returned as one-line strings.
//
// The TOML parser is toml++ 3.3 (Debian libtomlplusplus-dev), header-only, built with
// TOML_EXCEPTIONS=0. It was chosen over toml11 3.7.1 by fuzzing both (the evidence is in
// tests/bench/RESULTS.md, "Fuzzing"): toml++ validates UTF-8, bounds nesting, parses in
// linear time (a 64 KiB array: 17 ms against toml11's 2.2 s) and reports line:column of
// every error and of every value, without exceptions.
#include <cstddef>
#include <string>
#include <string_view>

// toml++ configuration, identical in every translation unit that includes it.
#define TOML_EXCEPTIONS 0
#define TOML_HEADER_ONLY 1
#define TOML_ENABLE_FORMATTERS 0  // we never print TOML through toml++ (its 3.3 formatter has UB on some floats)
// Nesting (arrays and inline tables within each other) deeper than this is a parse error
// (toml++ parses nesting recursively; 32 is far beyond any file of ours).
#define TOML_MAX_NESTED_VALUES 32
// toml++ 3.3's internal assertions include one that input can reach: the two bytes
// "[\n" fail `is_bare_key_character(*cp) || is_string_delimiter(*cp)` in parse_key()
// (found by fuzzing; tests/fuzz). Without its assertions the parser reports that input as
// the syntax error it is -- but with NDEBUG toml++ turns TOML_ASSERT_ASSUME into
// __builtin_assume under clang, so a false "assumption" would be undefined behaviour in
// optimised clang builds. Hence: its assertions are no-ops, and NDEBUG is hidden from it
// while it is included (that only drops its pure/const attributes), in every build.
#define TOML_ASSERT(expr) static_cast<void>(0)
#ifdef NDEBUG
#define SERVOARM_TOML_NDEBUG 1
#undef NDEBUG
#endif
#include <toml++/toml.h>
#ifdef SERVOARM_TOML_NDEBUG
#define NDEBUG 1
#undef SERVOARM_TOML_NDEBUG
#endif
#include <cassert>  // assert() as NDEBUG says again

namespace servoarm::kin {

/// Descriptions and configuration files are small (the largest built-in model is 3 KiB,
/// the shipped armfw.toml 3 KiB): anything larger is refused before it is parsed.
inline constexpr std::size_t kMaxInputFileBytes = 64 * 1024;

/// Read the whole of `path` into `text`. Only a regular file of at most `max_bytes` is
/// read (a directory, FIFO, device or socket is refused without blocking). Returns "" on
/// success, otherwise "<path>: <reason>" (cannot open: <errno text>, is a directory, not
/// a regular file, larger than N bytes, read error: <errno text>).
std::string read_text_file(const std::string& path, std::string& text, std::size_t max_bytes = kMaxInputFileBytes);

/// Replace `path` with `text` atomically: written to "<path>.tmp" in the same directory,
/// fsync'ed, renamed over `path`, and the directory fsync'ed, so that a power cut leaves
/// the old file or the new one, never part of one. Returns "" on success, otherwise
/// "<path>: <step> failed: <errno text>" (the old file is untouched, the temporary removed).
/// A symbolic link at `path` is replaced by a regular file (the link's target is untouched).
std::string write_text_file_atomic(const std::string& path, std::string_view text);

/// A parsed TOML document: `table` when `error` is empty.
struct TomlDocument {
  toml::table table;
  std::string error;  ///< "<origin>:<line>:<column>: not valid TOML: <reason>" (one line), or ""
};

/// Parse `text` (at most `max_bytes`, UTF-8, nesting within TOML_MAX_NESTED_VALUES).
/// Syntax errors, invalid UTF-8 (with the line and column of the first bad byte), a NUL
/// byte, numbers out of range (1e400) and oversize text are errors.
TomlDocument parse_toml(std::string_view text, const std::string& origin, std::size_t max_bytes = kMaxInputFileBytes);

/// "<origin>:<line>:<column>" of a node (or key) parsed from text, "<origin>" when the
/// node has no source position. Loaders start every value error with it.
std::string source_text(const toml::source_region& where, const std::string& origin);

/// What a value is, for messages: "a string", "an integer", "a number", "a boolean",
/// "an array", "a table", "a date/time".
const char* type_name(const toml::node& v);

/// `msg` as one line: control characters a file can put into a key or a string (newline,
/// tab, ...) written as \n, \t, \r or \xHH. Loaders pass every message through it.
std::string one_line(std::string msg);

/// A value as the file wrote it (strings quoted), shortened to about 40 characters.
std::string value_text(const toml::node& v);

}  // namespace servoarm::kin
