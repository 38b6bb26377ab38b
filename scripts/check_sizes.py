#!/usr/bin/env python3
"""Size limits that keep the code readable (docs/ARCHITECTURE.md), checked in `make test`.

  - no function over 150 lines, anywhere in src/, apps/, tests/, bench/ and fuzz/;
  - no file over 1,000 lines under src/node/, src/config/ and apps/.

One long, well-mapped library file may keep their long functions (LONG_FUNCTIONS_ALLOWED).
A function is a brace block at namespace or class scope whose head has a parameter list; comments,
strings and preprocessor lines are skipped first. TEST() bodies count as functions.

  scripts/check_sizes.py [ROOT]        exit 0: within the limits; 1: what is over is listed
  scripts/check_sizes.py --self-test   shows that a 151-line function and a 1,001-line file fail
"""
import os
import re
import subprocess
import sys

MAX_FUNCTION_LINES = 150
MAX_FILE_LINES = 1000
FILE_LIMITED = ("src/node/", "src/config/", "apps/")
SCANNED = ("src/", "apps/", "tests/", "bench/", "fuzz/", "include/")
LONG_FUNCTIONS_ALLOWED = {"src/crypto/mldsa65.cpp"}


def strip_code(src):
    """`src` with comments, string and character literals and preprocessor lines blanked
    (newlines kept, so line numbers stay)."""
    src = re.sub(r"(?m)^[ \t]*#.*(?:\\\n.*)*$", lambda m: "\n" * m.group(0).count("\n"), src)
    out, i, n = [], 0, len(src)
    while i < n:
        c = src[i]
        if src.startswith("//", i):
            j = src.find("\n", i)
            i = n if j < 0 else j
            continue
        if src.startswith("/*", i):
            j = src.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append("\n" * src.count("\n", i, j))
            i = j
            continue
        raw = re.match(r'R"([^()\\ ]{0,16})\(', src[i:i + 20])
        if raw and (i == 0 or not (src[i - 1].isalnum() or src[i - 1] == "_")):
            end = ")" + raw.group(1) + '"'
            j = src.find(end, i + len(raw.group(0)))
            j = n if j < 0 else j + len(end)
            out.append('""' + "\n" * src.count("\n", i, j))
            i = j
            continue
        if c == '"' or (c == "'" and not (i > 0 and src[i - 1].isalnum())):
            j = i + 1
            while j < n and src[j] != c:
                j += 2 if src[j] == "\\" else 1
            out.append(c + c)
            i = j + 1
            continue
        out.append(c)
        i += 1
    return "".join(out)


def functions(text):
    """(lines, first line, head) of every function body in `text`."""
    s = strip_code(text)
    found, stack, seg, line = [], [], 0, 1
    for i, c in enumerate(s):
        if c == "\n":
            line += 1
        elif c == "{":
            head = re.sub(r"\s+", " ", s[seg:i]).strip()
            at_scope = all(k in ("namespace", "class") for k, _, _ in stack)
            kind = "block"
            if re.search(r"\b(namespace|extern)\b", head) and "(" not in head:
                kind = "namespace"
            elif re.search(r"\b(class|struct|union|enum)\b[^()]*$", head):
                kind = "class"
            elif at_scope and ")" in head and not re.match(r"(if|for|while|switch|catch)\b", head) \
                    and "=" not in head.split("(")[0]:
                kind = "function"
            stack.append((kind, line, head[-100:]))
            seg = i + 1
        elif c == "}":
            if stack:
                kind, first, head = stack.pop()
                if kind == "function":
                    found.append((line - first + 1, first, head))
            seg = i + 1
        elif c == ";":
            seg = i + 1
    return found


def tracked(root):
    try:
        out = subprocess.run(["git", "-C", root, "ls-files", "--cached", "--others", "--exclude-standard"],
                             capture_output=True, text=True, check=True).stdout.split("\n")
    except (OSError, subprocess.CalledProcessError):
        out = [os.path.relpath(os.path.join(d, f), root) for d, _, fs in os.walk(root) for f in fs]
    return sorted(f for f in out if f.startswith(SCANNED) and f.endswith((".cpp", ".h"))
                  and "/node_modules/" not in f and os.path.isfile(os.path.join(root, f)))


def check(root):
    problems = []
    files = tracked(root)
    for path in files:
        with open(os.path.join(root, path), encoding="utf-8", errors="replace") as fh:
            text = fh.read()
        lines = text.count("\n")
        if path.startswith(FILE_LIMITED) and lines > MAX_FILE_LINES:
            problems.append(f"{path}: {lines} lines (at most {MAX_FILE_LINES} under "
                            f"{', '.join(FILE_LIMITED)})")
        if path in LONG_FUNCTIONS_ALLOWED:
            continue
        for n, first, head in functions(text):
            if n > MAX_FUNCTION_LINES:
                problems.append(f"{path}:{first}: a function of {n} lines (at most "
                                f"{MAX_FUNCTION_LINES}): {head}")
    for p in problems:
        print(p)
    print(f"check_sizes: {len(files)} files, {len(problems)} over the limits")
    return problems


def self_test():
    import shutil
    import tempfile
    d = tempfile.mkdtemp(prefix="check_sizes.")
    try:
        os.makedirs(os.path.join(d, "src/node"))
        def fn(lines):  # a function of `lines` lines, with a brace in a comment and a string
            body = [f"  x += {i};  // {{" if i % 2 else f'  s = "}}{i}";' for i in range(lines - 2)]
            return "int f(int x) {\n" + "\n".join(body) + "\n}\n"

        def write(name, text):
            with open(os.path.join(d, name), "w", encoding="utf-8") as fh:
                fh.write(text)
        write("src/node/a.cpp", fn(150))
        good = not check(d)
        write("src/node/a.cpp", fn(151))
        long_fn = any("a function of 151 lines" in p for p in check(d))
        write("src/node/a.cpp", "int x;\n" * 1001)
        long_file = any("1001 lines" in p for p in check(d))
        print(f"150-line function passes: {good}; 151-line function fails: {long_fn}; "
              f"1,001-line file fails: {long_file}")
        return 0 if good and long_fn and long_file else 1
    finally:
        shutil.rmtree(d, ignore_errors=True)


def main():
    if sys.argv[1:] == ["--self-test"]:
        return self_test()
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..")
    return 1 if check(os.path.abspath(root)) else 0


if __name__ == "__main__":
    sys.exit(main())
