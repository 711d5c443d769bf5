#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""The folders' dependencies as docs/design.md's layout table gives them ("may depend on").

Reads every `#include "servoarm/..."` (or <servoarm/...>) of the project's sources and
headers (kinematics/, hal/, host_sim/, firmware/; not tests/), finds the folder that
provides the header (the one whose include/ holds it), and fails, naming the file and
line, when
  - a folder includes a folder that ALLOWED below does not list for it,
  - the folders include each other in a loop (whatever the table says),
  - an included servoarm/ header is provided by no folder.

    check_layering.py <source root>
"""
import pathlib
import re
import sys

# folder -> the folders it may include besides itself: a layer only reaches down.
ALLOWED = {
    "kinematics/io": [],
    "kinematics": ["kinematics/io"],  # the description loader (servoarm_kin_desc) reads files
    "hal": ["kinematics"],
    "host_sim": ["hal", "kinematics", "kinematics/io"],
    "firmware/rt": ["kinematics", "hal"],
    "firmware/config": ["firmware/lang", "kinematics", "kinematics/io", "hal"],
    "firmware/lang": ["kinematics", "kinematics/io"],
    "firmware/program": ["firmware/lang", "kinematics", "kinematics/io"],
    "firmware/service": ["firmware/program", "firmware/lang", "firmware/rt", "kinematics", "kinematics/io", "hal"],
    "firmware/api": ["firmware/service", "firmware/lang", "firmware/rt", "kinematics", "kinematics/io", "hal"],
    "firmware/console": ["firmware/service", "firmware/program", "firmware/lang", "firmware/rt", "kinematics", "kinematics/io", "hal"],
    "firmware/app": ["firmware/api", "firmware/console", "firmware/service", "firmware/program", "firmware/lang", "firmware/rt", "firmware/config",
                     "kinematics", "kinematics/io", "hal", "host_sim"],
    "firmware/armctl": ["firmware/service", "firmware/program", "firmware/lang", "firmware/config", "kinematics", "kinematics/io", "hal"],
}
# (folder, included folder) -> the only files of the folder that may include it.
ONLY_FROM = {
    ("firmware/app", "host_sim"): {"firmware/app/src/armfw_main.cpp"},  # --sim; App itself links no simulator
}
TOPS = ("kinematics", "hal", "host_sim", "firmware")
INCLUDE = re.compile(r'^\s*#\s*include\s*[<"](servoarm/[^>"]+)[>"]')


def folder_of(rel: str) -> str | None:
    """The folder (a key of ALLOWED) that owns a path relative to the root."""
    parts = rel.split("/")
    if parts[0] == "firmware" and len(parts) > 2:
        return "firmware/" + parts[1]
    if parts[0] == "kinematics" and len(parts) > 2 and parts[1] == "io":
        return "kinematics/io"
    return parts[0] if parts[0] in TOPS[:3] else None


def main() -> int:
    root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ".").resolve()
    files = [p for top in TOPS for p in sorted((root / top).rglob("*"))
             if p.suffix in (".cpp", ".hpp", ".h") and p.is_file()]
    # header path as included ("servoarm/rt/controller.hpp") -> the folder that provides it
    provider: dict[str, str] = {}
    for p in files:
        rel = p.relative_to(root).as_posix()
        m = re.search(r"/include/(servoarm/.+)$", rel)
        if m and folder_of(rel):
            provider[m.group(1)] = folder_of(rel)
    errors = []
    edges: dict[str, dict[str, str]] = {}  # folder -> included folder -> first "file:line"
    for p in files:
        rel = p.relative_to(root).as_posix()
        src = folder_of(rel)
        if src is None:
            continue
        if src not in ALLOWED:
            errors.append(f"{rel}: folder {src} is not in the table of check_layering.py (add it with what it may include)")
            continue
        for n, line in enumerate(p.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            m = INCLUDE.match(line)
            if not m:
                continue
            dst = provider.get(m.group(1))
            where = f"{rel}:{n}"
            if dst is None:
                errors.append(f"{where}: includes {m.group(1)}, which no folder provides")
                continue
            if dst == src:
                continue
            edges.setdefault(src, {}).setdefault(dst, where)
            if dst not in ALLOWED[src]:
                errors.append(f"{where}: {src} includes {m.group(1)} ({dst}); {src} may include only "
                              f"{', '.join(ALLOWED[src]) or 'itself'}")
            elif (src, dst) in ONLY_FROM and rel not in ONLY_FROM[(src, dst)]:
                errors.append(f"{where}: {src} includes {m.group(1)} ({dst}), which only "
                              f"{', '.join(sorted(ONLY_FROM[(src, dst)]))} may")
    # loops between folders, found in the includes themselves
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(f: str) -> None:
        state[f] = 1
        stack.append(f)
        for g in sorted(edges.get(f, {})):
            if state.get(g) == 1:
                loop = stack[stack.index(g):] + [g]
                hops = "; ".join(f"{a} -> {b} ({edges[a][b]})" for a, b in zip(loop, loop[1:]))
                errors.append(f"include loop between folders: {hops}")
            elif g not in state:
                visit(g)
        stack.pop()
        state[f] = 2

    for f in sorted(edges):
        if f not in state:
            visit(f)
    for e in errors:
        print(e)
    if errors:
        print(f"{len(errors)} layering error(s); the table is docs/design.md's layout (\"may depend on\")")
        return 1
    print(f"{len(files)} files, {sum(len(v) for v in edges.values())} folder dependencies, all allowed, no loop")
    return 0


if __name__ == "__main__":
    sys.exit(main())
