#!/usr/bin/env python3
"""The bottom layer's two rules (docs/ARCHITECTURE.md), checked on every source file.

  - Time is read only in src/base (src/base/clock.h: steady_now(), wall_now(), steady_ms(),
    unix_ms(), ...; or an injected Clock): a raw std::chrono::*_clock::now() or std::time()
    elsewhere fails, so that one place says which clock a deadline or a timestamp comes from.
  - ASCII case folding is src/base/strings.h's ascii_lower()/ascii_upper(): a private
    lower()/upper()/to_lower()/to_upper()/ascii_lower()/ascii_upper() definition elsewhere fails.

  scripts/check_primitives.py [ROOT]      exit 0: no violation; 1: some (file:line printed)
  scripts/check_primitives.py --self-test  shows that the check fails on a raw clock read and on
                                           a private lower() (in a temporary tree)
"""
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import check_tree  # noqa: E402  (scripts/check_tree.py)

SCANNED = ("include/", "src/", "apps/")
BOTTOM = "src/base/"
# Files that still read the clock themselves or keep a private lower(); each entry is to be
# emptied, not extended.
ALLOWED: set = set()  # files not yet changed over; none
CLOCK_RE = re.compile(r"\b(steady_clock|system_clock|high_resolution_clock|utc_clock|file_clock)"
                      r"\s*::\s*now\s*\(|\bstd::time\s*\(")
CASE_RE = re.compile(r"^\s*(?:static\s+|inline\s+)*(?:std::string|auto)\s+"
                     r"(?:ascii_)?(?:to_)?(?:lower|upper)\s*\([^;]*$")


def code_of(line):
    """`line` without a // comment (a clock named in a comment is not a read)."""
    at = line.find("//")
    return line if at < 0 else line[:at]


def sources(root):
    for top in SCANNED:
        for dirpath, _, files in os.walk(os.path.join(root, top)):
            for f in files:
                if f.endswith((".h", ".cpp")):
                    yield os.path.relpath(os.path.join(dirpath, f), root).replace(os.sep, "/")


def check(root):
    errors, files = [], sorted(sources(root))
    for path in files:
        if path.startswith(BOTTOM) or path in ALLOWED:
            continue
        with open(os.path.join(root, path), encoding="utf-8", errors="replace") as fh:
            for lineno, line in enumerate(fh, 1):
                code = code_of(line)
                if CLOCK_RE.search(code):
                    errors.append(f"{path}:{lineno}: raw clock read (use src/base/clock.h or an "
                                  f"injected Clock): {line.strip()}")
                if CASE_RE.match(code):
                    errors.append(f"{path}:{lineno}: private case folding (use ascii_lower/"
                                  f"ascii_upper of src/base/strings.h): {line.strip()}")
    for e in errors:
        print(e)
    print(f"check_primitives: {len(files)} files, {len(ALLOWED)} allowed, {len(errors)} violation(s)")
    return errors


def self_test():
    """A tree that follows the rules, then each rule broken once: each break must be caught."""

    ok_tree = {
        "src/base/clock.h": "inline auto steady_now() { return std::chrono::steady_clock::now(); }\n",
        "src/core/a.cpp": "// steady_clock::now() named in a comment is no read\nint f() { return 1; }\n",
    }
    cases = [
        ("a tree that follows the rules", {}, None),
        ("a raw steady clock read", {"src/node/x.cpp": "auto t = std::chrono::steady_clock::now();\n"},
         "raw clock read"),
        ("a raw time() read", {"apps/rcan/y.cpp": "long t = std::time(nullptr);\n"}, "raw clock read"),
        ("a private lower()", {"src/core/b.cpp": "std::string lower(std::string_view s) {\n}\n"},
         "private case folding"),
    ]
    return check_tree.run_self_test("check_primitives.", ok_tree, cases, check, "no violation")


if __name__ == "__main__":
    sys.exit(check_tree.main(check, self_test))
