#!/usr/bin/env python3
"""The folder map of docs/ARCHITECTURE.md against the tree, and the paths the docs name.

  - Every folder of the tree (under src/, include/ and apps/ three levels deep, e.g.
    src/node/api; under tests/, fuzz/, web/ and third_party/ two, e.g. tests/e2e; bench/ and
    scripts/ themselves) appears in the map (the tables of the section "## The folder map": every
    `folder/` in a row's first cell), and every folder the map names exists. A row whose first
    cell says "(planned)" names a folder that may not exist yet.
  - Every path of the source tree that docs/*.md or README.md names (src/..., apps/...,
    tests/..., include/..., bench/..., fuzz/..., scripts/..., web/..., third_party/...; globs
    like grpc_*.cpp and braces like x.{h,cpp} included; a program, bench/fleet_bench, by its
    source) exists.

  scripts/check_folder_map.py [ROOT]      exit 0: map and paths agree with the tree; 1: they do not
  scripts/check_folder_map.py --self-test  shows that the check fails on a folder missing from the
                                           map, a mapped folder that does not exist and a stale
                                           path in a doc (in a temporary tree)
"""
import glob
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import check_tree  # noqa: E402  (scripts/check_tree.py)

MAP_DOC = "docs/ARCHITECTURE.md"
MAP_HEADING = "## The folder map"
# How deep the map must go under each top folder (path components, the top one included).
DEPTH = {"src": 3, "include": 3, "apps": 2, "tests": 2, "fuzz": 2, "web": 2, "bench": 1,
         "scripts": 1, "third_party": 2}
TOPS = tuple(DEPTH)
SKIP_DIRS = {"__pycache__", "node_modules"}
PATH_RE = re.compile(r"(?<![\w./<>-])((?:%s)/[A-Za-z0-9_.*{},+/-]*)" % "|".join(TOPS))


def tree_folders(root):
    out = set()
    for top, depth in DEPTH.items():
        base = os.path.join(root, top)
        if not os.path.isdir(base):
            continue
        out.add(top + "/")
        for dirpath, dirs, _ in os.walk(base):
            dirs[:] = [d for d in dirs if d not in SKIP_DIRS and not d.startswith(".")]
            rel = os.path.relpath(dirpath, root).replace(os.sep, "/")
            if rel.count("/") + 1 >= depth:
                dirs[:] = []
            out.add(rel + "/")
    return out


def map_folders(root):
    """{folder: planned} for every folder named in the first cell of the map's table rows."""
    with open(os.path.join(root, MAP_DOC), encoding="utf-8") as fh:
        text = fh.read()
    at = text.find("\n" + MAP_HEADING)
    if at < 0:
        return None
    section = text[at + 1:]
    end = section.find("\n## ", 1)
    section = section if end < 0 else section[:end]
    named = {}
    for line in section.splitlines():
        if not line.startswith("|") or line.startswith("|---"):
            continue
        cell = line.split("|")[1]
        for f in re.findall(r"`([^`]+/)`", cell):
            named[f] = "(planned)" in cell
    return named


def expand(path):
    """`path` with {a,b} alternatives expanded."""
    m = re.search(r"\{([^{}]*)\}", path)
    if not m:
        return [path]
    return [x for alt in m.group(1).split(",")
            for x in expand(path[:m.start()] + alt + path[m.end():])]


def stale_paths(root):
    docs = sorted(glob.glob(os.path.join(root, "docs", "*.md"))) + [os.path.join(root, "README.md")]
    out = []
    for doc in docs:
        if not os.path.isfile(doc):
            continue
        rel = os.path.relpath(doc, root).replace(os.sep, "/")
        with open(doc, encoding="utf-8") as fh:
            for lineno, line in enumerate(fh, 1):
                if "(planned)" in line:
                    continue  # a folder the map announces
                for m in PATH_RE.finditer(line):
                    p = m.group(1).rstrip(".,;:")
                    if p.endswith("/*"):
                        p = p[:-1]
                    if p.count("/") == 0 or "..." in p:
                        continue
                    # A program's name (bench/fleet_bench) stands for its source file.
                    found = all(glob.glob(os.path.join(root, x)) or glob.glob(os.path.join(root, x + ".*"))
                                for x in expand(p))
                    if not found:
                        out.append(f"{rel}:{lineno}: names {p}, which does not exist")
    return out


def check(root):
    errors = []
    named = map_folders(root)
    if named is None:
        errors.append(f"{MAP_DOC}: no section '{MAP_HEADING}'")
        named = {}
    tree = tree_folders(root)
    for f in sorted(tree - set(named)):
        errors.append(f"{f}: not in the folder map ({MAP_DOC}, '{MAP_HEADING}')")
    for f, planned in sorted(named.items()):
        if not planned and not os.path.isdir(os.path.join(root, f)):
            errors.append(f"{MAP_DOC}: the folder map names {f}, which does not exist")
    errors += stale_paths(root)
    for e in errors:
        print(e)
    print(f"check_folder_map: {len(tree)} folders in the tree, {len(named)} in the map, "
          f"{len(errors)} problem(s)")
    return errors


def self_test():
    """A tree whose map and docs agree with it, then each way to disagree: each must be caught."""

    good = {
        "src/core/a.cpp": "",
        "apps/rcan/main.cpp": "",
        "README.md": "The CLI: `apps/rcan/main.cpp`; the core: src/core/.\n",
        MAP_DOC: ("# Architecture\n\n" + MAP_HEADING + "\n\n| folder | what |\n|---|---|\n"
                  "| `src/` | sources |\n| `src/core/` | the core |\n| `apps/` | programs |\n"
                  "| `apps/rcan/` | the CLI |\n| `tests/install/` (planned) | later |\n\n## Next\n"),
    }
    cases = [
        ("a tree that agrees with its map", {}, None),
        ("a folder missing from the map", {"src/crypto/b.cpp": ""}, "not in the folder map"),
        ("a mapped folder that does not exist",
         {MAP_DOC: good[MAP_DOC].replace("| `apps/` |", "| `src/gone/` | x |\n| `apps/` |")},
         "which does not exist"),
        ("a stale path in a doc", {"docs/X.md": "See `src/core/gone.cpp`.\n"}, "does not exist"),
    ]
    return check_tree.run_self_test("check_folder_map.", good, cases, check, "no problem")


if __name__ == "__main__":
    sys.exit(check_tree.main(check, self_test))
