#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""The manual reads like a manual: docs/*.md say what the software does and why, not its
history. Fails, naming file:line, on
  - an issue reference ("issue 35", "Issue 18.", "issues 34, 35"): the tracker is not the manual;
  - an undefined reference: "seed 002 §3.14" or a "§" with no source named before it in the
    same paragraph (an emphasised title, *Apostila de Robótica*, or a link);
  - a dated history line: a date (2026-12-04, 4 December 2026) in the text. Measurements and
    their dates belong in tests/bench/RESULTS.md, which a page links.
Usage: check-manual.py REPO_ROOT [FILE...]  (default: every docs/*.md)"""
import pathlib
import re
import sys
import tempfile

ISSUE = re.compile(r"\bissues?\s+#?\d+", re.I)
SEED = re.compile(r"\bseeds?\s+\d+", re.I)
DATE = re.compile(r"\b20\d\d-\d\d-\d\d\b|\b\d{1,2} (January|February|March|April|May|June|July|August|"
                  r"September|October|November|December) 20\d\d\b")
SOURCE = re.compile(r"(?<![*\w])\*[^*\s][^*]*\*(?!\*)|(?<!\w)_[^_\s][^_]*_(?!\w)|\]\(")  # *Title*, _Title_, a link


def problems(path: pathlib.Path):
    text = path.read_text(encoding="utf-8")
    out = []
    paragraph = ""  # the paragraph so far, for a § whose source came earlier in it
    fence = False
    for n, line in enumerate(text.splitlines(), 1):
        if line.startswith("```"):
            fence = not fence
        if not line.strip():
            paragraph = ""
        for m in ISSUE.finditer(line):
            out.append(f"{path}:{n}: issue reference '{m.group(0)}': say what and why, not which issue")
        for m in SEED.finditer(line):
            out.append(f"{path}:{n}: undefined reference '{m.group(0)}': cite author, title, section (or drop it)")
        for m in DATE.finditer(line):
            if "anchor" in line or "RESULTS.md#" in line[max(0, m.start() - 80):m.end() + 80]:
                continue  # a link to a dated RESULTS.md entry names the entry, it is not history
            out.append(f"{path}:{n}: dated history '{m.group(0)}': figures and dates go to tests/bench/RESULTS.md")
        for m in re.finditer("§", line):
            if not fence and not SOURCE.search(paragraph + line[:m.start()]):
                out.append(f"{path}:{n}: '§' with no source named before it in its paragraph")
        paragraph += line + "\n"
    return out


def main():
    root = pathlib.Path(sys.argv[1])
    files = [root / f for f in sys.argv[2:]] or sorted((root / "docs").glob("*.md"))
    found = [p for f in files for p in problems(f)]
    for p in found:
        print(p)
    # the checks themselves: each kind of line is caught, a sourced § is not
    samples = {
        "see issue 35": 1, "Issue 18. What is built": 1, "seed 002 §3.14": 2, "Measured 2026-12-04 on": 1,
        "three runs, 4 December 2026": 1, "*Apostila de Robótica*, §3.14": 0, "§4.2 of the design": 1,
    }
    for s, want in samples.items():
        with tempfile.TemporaryDirectory() as d:
            tmp = pathlib.Path(d) / "sample.md"
            tmp.write_text(s + "\n", encoding="utf-8")
            got = len(problems(tmp))
        if got != want:
            print(f"check-manual.py itself: '{s}' gives {got} findings, expected {want}")
            found.append(s)
    print(f"{len(files)} pages, {len(found)} findings")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
