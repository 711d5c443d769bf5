#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Every armctl command shown in the manual runs as shown.

Usage: check-examples.py ARMCTL SOURCE_DIR [PAGE.md ...]
       (default pages: README.md and docs/*.md of SOURCE_DIR)

What counts as an example
  A line inside a fenced block whose info string is empty, `sh`, `bash` or `shell`
  that starts (after blanks and an optional `$ ` prompt) with `armctl ` or
  `build/bin/armctl `; a line ending in a backslash continues on the next one.
  A synopsis (`--robot NAME|FILE [--grid N]`) is not an example: it goes in a
  ```text block. Lines of other blocks and of the text are not read.

How it runs
  The example's words (shell quoting) up to the first shell operator (`|`, `>`,
  `<`, `&&`, `||`, `;`, `&`) are armctl and its arguments; they run without a
  shell (what the shell would do with the output is not checked), stdin empty,
  120 s at most (under $SERVOARM_TEST_EMULATOR, e.g. qemu-arm, when it is set:
  a cross build), in a fresh directory that holds a link to every top-level entry
  of the source tree (so `firmware/program/examples/...` resolves) and the files
  of tests/docs/files/: stand-ins for a reader's own files that the examples name
  (my_arm.toml, prog.arm, points.toml). Files an example writes land there.

Markers: a trailing shell comment on the example's last line
  # refused: WHY   the example shows a refusal: armctl must exit 1 or 2 with
                   exactly one line on stderr, `armctl: ...`.
  # needs: WHAT    not run: it needs what no test has (a serial device, a CAN
                   interface with armfw on it); listed as not run.
  Any other comment is a remark: the example must exit 0.
Exit status: 0 when every example did what it shows, 1 otherwise (each failure
is one line: page:line, the command, what it printed).
"""
import glob
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile

SHELL_BLOCKS = {"", "sh", "bash", "shell"}
START = re.compile(r"^\s*(?:\$\s+)?((?:build/bin/)?armctl\s.*)$")
OPERATORS = {"|", "||", "&", "&&", ";", ";;", ">", ">>", "<", "<<", ">&", "<&", "(", ")", "|&"}
MARKER = re.compile(r"^#\s*(refused|needs):\s*(.*)$")


def examples(path, rel):
    """(page:line, logical line) of every example on one page."""
    out = []
    fence = None  # the fence's info string while inside a block
    pending = None  # [where, text] of an example continued with a backslash
    with open(path, encoding="utf-8") as f:
        lines = f.read().split("\n")
    for n, line in enumerate(lines, 1):
        m = re.match(r"^\s*(```+|~~~+)\s*([^\s`]*)", line)
        if m:
            fence = m.group(2).lower() if fence is None else None
            pending = None
            continue
        if fence is None or fence not in SHELL_BLOCKS:
            continue
        if pending is not None:
            pending[1] += " " + line.strip()
        else:
            s = START.match(line)
            if not s:
                continue
            pending = ["%s:%d" % (rel, n), s.group(1).strip()]
        if pending[1].endswith("\\"):
            pending[1] = pending[1][:-1].rstrip()
        else:
            out.append(tuple(pending))
            pending = None
    return out


def split_comment(text):
    """(command, comment) of one logical line: a `#` that starts a word outside quotes
    begins the comment, as in the shell."""
    quote, prev, escaped = None, " ", False
    for i, c in enumerate(text):
        if escaped:
            escaped = False
        elif c == "\\" and quote != "'":
            escaped = True
        elif quote:
            if c == quote:
                quote = None
        elif c in "'\"":
            quote = c
        elif c == "#" and prev in " \t;|&":
            return text[:i], text[i:].strip()
        prev = c
    return text, ""


def parse(text):
    """(argv, marker kind or None, marker text) of one example."""
    command, comment = split_comment(text)
    lex = shlex.shlex(command, posix=True, punctuation_chars=True)
    lex.whitespace_split = True
    lex.commenters = ""
    argv = []
    for w in lex:
        if w in OPERATORS:
            break  # the command ends here
        argv.append(w)
    kind, why = None, ""
    m = MARKER.match(comment)
    if m:
        kind, why = m.group(1), m.group(2).strip()
    return argv, kind, why


def main():
    if len(sys.argv) < 3:
        sys.stderr.write("usage: check-examples.py ARMCTL SOURCE_DIR [PAGE.md ...]\n")
        return 2
    armctl, src = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
    pages = sys.argv[3:] or [os.path.join(src, "README.md")] + sorted(glob.glob(os.path.join(src, "docs", "*.md")))
    files = os.path.join(src, "tests", "docs", "files")
    prefix = shlex.split(os.environ.get("SERVOARM_TEST_EMULATOR", ""))
    no_urdf = os.environ.get("SERVOARM_DOCS_NO_URDF", "") == "1"
    found, failed, not_run = 0, [], []
    for page in pages:
        rel = os.path.relpath(os.path.abspath(page), src)
        for where, text in examples(page, rel):
            found += 1
            try:
                argv, kind, why = parse(text)
            except ValueError as e:  # unbalanced quotes
                failed.append("%s: %s: cannot split into words (%s)" % (where, text, e))
                continue
            if kind == "needs":
                if not why:
                    failed.append("%s: %s: '# needs:' says nothing about what is needed" % (where, text))
                else:
                    not_run.append("%s: %s (needs %s)" % (where, " ".join(argv), why))
                continue
            if no_urdf and any(w == "urdf" or w.endswith(".urdf") for w in argv):
                # an armctl built without urdfdom (a cross build: no target urdfdom) refuses these
                not_run.append("%s: %s (needs an armctl built with urdfdom)" % (where, " ".join(argv)))
                continue
            if kind == "refused" and not why:
                failed.append("%s: %s: '# refused:' says nothing about why" % (where, text))
                continue
            run = tempfile.mkdtemp(prefix="servoarm_docs_")
            try:
                for e in os.listdir(src):
                    if not e.startswith(".") and e != "build":
                        os.symlink(os.path.join(src, e), os.path.join(run, e))
                for e in os.listdir(files):
                    shutil.copy(os.path.join(files, e), run)
                try:
                    p = subprocess.run(prefix + [armctl] + argv[1:], cwd=run, stdin=subprocess.DEVNULL,
                                       capture_output=True, text=True, timeout=120)
                    rc, err = p.returncode, p.stderr
                except subprocess.TimeoutExpired:
                    rc, err = None, "(no end within 120 s)"
            finally:
                shutil.rmtree(run, ignore_errors=True)
            err_lines = [x for x in err.split("\n") if x.strip()]
            first = err_lines[0] if err_lines else "(nothing on stderr)"
            shown = " ".join(argv)
            if kind == "refused":
                if rc not in (1, 2):
                    failed.append("%s: %s: shown as refused (%s) but exits %s, not 1 or 2; stderr: %s"
                                  % (where, shown, why, rc, first))
                elif len(err_lines) != 1 or not err_lines[0].startswith("armctl: "):
                    failed.append("%s: %s: refused with %d lines on stderr, not one 'armctl: ...' line: %s"
                                  % (where, shown, len(err_lines), " | ".join(err_lines[:3])))
                else:
                    print("ok (refused: %s) %s: %s\n    %s" % (why, where, shown, first))
            elif rc != 0:
                failed.append("%s: %s: exits %s, the page shows it running; stderr: %s" % (where, shown, rc, first))
            else:
                print("ok %s: %s" % (where, shown))
    for x in not_run:
        print("not run: " + x)
    for x in failed:
        print("FAIL " + x)
    print("%d examples: %d ran as shown, %d not run (marked # needs:), %d failed"
          % (found, found - len(not_run) - len(failed), len(not_run), len(failed)))
    if found == 0:
        print("FAIL no armctl example found: has the extraction broken?")
        return 1
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
