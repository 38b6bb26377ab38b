#!/usr/bin/env python3
"""The lock rules of the node, its base, its transports, its drivers and the audit log, checked by
Clang's thread-safety analysis (src/base/thread_annotations.h) in `make test`.

Every .cpp under src/node/, src/base/, src/runtime/, src/transport/, src/drivers/ and src/audit/
is compiled with clang++ (14 or later) -fsyntax-only -Wthread-safety -Werror=thread-safety, with
the include paths and definitions the build uses (the release tree's compile_commands.json). A
member GUARDED_BY a
mutex touched without it, a REQUIRES function called without the lock, an EXCLUDES function
called with it or a lock left held on some path fails the check, with clang's diagnostic.

  scripts/check_thread_safety.py --build DIR [ROOT]   exit 0: no finding; 1: findings (printed)
  scripts/check_thread_safety.py --self-test          shows that a guarded member written
                                                      without its lock fails (in a temporary tree)
Options: --jobs N (default 2) compilers at a time; --clang PATH (default: $CLANGXX, else
clang++-14, else clang++); --only PREFIX (repeatable) checks only the files whose path starts
with it (e.g. --only src/node/control/).
"""
import argparse
import concurrent.futures
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time

CHECKED = ("src/node/", "src/base/", "src/runtime/", "src/transport/", "src/drivers/", "src/audit/")
CHECK_FLAGS = ["-fsyntax-only", "-std=c++20", "-Wthread-safety", "-Werror=thread-safety"]
# What is kept of the build's command line: where headers are and what is defined.
KEPT_WITH_VALUE = {"-I", "-isystem", "-iquote", "-idirafter", "-D", "-U", "-include"}
KEPT_PREFIXES = ("-I", "-D", "-U", "-isystem", "-iquote")


def find_clang(explicit):
    for c in (explicit, os.environ.get("CLANGXX"), "clang++-14", "clang++"):
        if c and shutil.which(c):
            return shutil.which(c)
    return None


def sources(root):
    for top in CHECKED:
        for dirpath, _, files in os.walk(os.path.join(root, top)):
            for f in sorted(files):
                if f.endswith(".cpp"):
                    yield os.path.relpath(os.path.join(dirpath, f), root)


def include_flags(entry):
    """The -I/-isystem/-D/... arguments of one compile_commands.json entry, relative paths made
    absolute against the entry's directory."""
    args = entry.get("arguments") or shlex.split(entry["command"])
    out, i = [], 1
    while i < len(args):
        a = args[i]
        if a in KEPT_WITH_VALUE and i + 1 < len(args):
            value = args[i + 1]
            if a not in ("-D", "-U") and not os.path.isabs(value):
                value = os.path.join(entry["directory"], value)
            out += [a, value]
            i += 2
            continue
        if a.startswith(KEPT_PREFIXES):
            if a.startswith("-I") and not os.path.isabs(a[2:]):
                a = "-I" + os.path.join(entry["directory"], a[2:])
            out.append(a)
        i += 1
    return out


def load_commands(path, root):
    """{repository path: include flags} for the checked files in compile_commands.json."""
    with open(path, encoding="utf-8") as fh:
        entries = json.load(fh)
    commands = {}
    for e in entries:
        f = os.path.normpath(os.path.join(e["directory"], e["file"]))
        rel = os.path.relpath(f, root)
        if rel.startswith(CHECKED) and rel not in commands:
            commands[rel] = include_flags(e)
    return commands


def compile_one(clang, root, rel, flags):
    started = time.monotonic()
    proc = subprocess.run([clang, *CHECK_FLAGS, *flags, os.path.join(root, rel)],
                          cwd=root, capture_output=True, text=True)
    return rel, proc.returncode, proc.stderr, time.monotonic() - started


def check(root, build, jobs, clang, only=()):
    """The files that failed (their diagnostics printed) — or every file, when the check
    cannot run."""
    files = sorted(f for f in sources(root) if not only or f.startswith(tuple(only)))
    db = os.path.join(build, "compile_commands.json")
    if clang is None:
        print("check_thread_safety: no clang++ found (scripts/install-deps.sh installs clang-14)")
        return files or ["(no clang)"]
    if not os.path.isfile(db):
        print(f"check_thread_safety: {db} not found (configure the tree first)")
        return files or ["(no compile_commands.json)"]
    commands = load_commands(db, root)
    failed = [f for f in files if f not in commands]
    for f in failed:
        print(f"{f}: not in {db} (a source the build does not compile?)")
    started, slowest = time.monotonic(), ("", 0.0)
    with concurrent.futures.ThreadPoolExecutor(max_workers=max(jobs, 1)) as pool:
        runs = [pool.submit(compile_one, clang, root, f, commands[f]) for f in files if f in commands]
        for run in concurrent.futures.as_completed(runs):
            rel, rc, err, took = run.result()
            slowest = max(slowest, (rel, took), key=lambda s: s[1])
            if rc != 0:
                failed.append(rel)
                print(f"---- {rel}\n{err.rstrip()}")
                if "file not found" in err:
                    print("(a generated header is missing? build the tree before the check)")
    print(f"check_thread_safety: {len(files)} files, {len(failed)} failed, "
          f"{time.monotonic() - started:.0f} s ({os.path.basename(clang)}, {jobs} jobs; "
          f"slowest {slowest[0]}, {slowest[1]:.0f} s)")
    return failed


SELF_TEST_GOOD = """#include "base/thread_annotations.h"
namespace rcan {
class Counter {
 public:
  void add(int n) EXCLUDES(mu_) {
    MutexLock lock(mu_);
    add_locked(n);
  }
  int wait_for_positive() EXCLUDES(mu_) {
    ReleasableMutexLock lock(mu_);
    while (value_ <= 0) cv_.wait(mu_);
    const int v = value_;
    lock.unlock();
    return v;
  }

 private:
  void add_locked(int n) REQUIRES(mu_) {
    value_ += n;
    cv_.notify_all();
  }
  Mutex mu_;
  CondVar cv_;
  int value_ GUARDED_BY(mu_) = 0;
};
}  // namespace rcan
"""

SELF_TEST_CASES = [
    ("a class that follows its lock rules", {}, None),
    ("a guarded member written without its lock",
     {"void add(int n) EXCLUDES(mu_) {\n    MutexLock lock(mu_);\n    add_locked(n);":
      "void add(int n) EXCLUDES(mu_) {\n    value_ += n;\n    MutexLock lock(mu_);"},
     "writing variable 'value_' requires holding mutex 'mu_'"),
    ("a REQUIRES helper called without the lock",
     {"    MutexLock lock(mu_);\n    add_locked(n);": "    add_locked(n);"},
     "calling function 'add_locked' requires holding mutex 'mu_'"),
    ("a guarded member read after unlock()",
     {"    const int v = value_;\n    lock.unlock();": "    lock.unlock();\n    const int v = value_;"},
     "reading variable 'value_' requires holding mutex 'mu_'"),
]


def self_test(clang):
    """A small tree with one annotated class, compiled as it is and broken three ways: the
    correct one must pass and each broken one must fail with the expected diagnostic."""
    import contextlib
    import io

    here = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
    failed = 0
    for name, edits, expect in SELF_TEST_CASES:
        print(f"-- {name}")
        d = tempfile.mkdtemp(prefix="check_thread_safety.")
        try:
            os.makedirs(os.path.join(d, "src/base"))
            os.makedirs(os.path.join(d, "src/node/x"))
            shutil.copy(os.path.join(here, "src/base/thread_annotations.h"), os.path.join(d, "src/base"))
            text = SELF_TEST_GOOD
            for old, new in edits.items():
                assert old in text, old
                text = text.replace(old, new)
            with open(os.path.join(d, "src/node/x/counter.cpp"), "w", encoding="utf-8") as fh:
                fh.write(text)
            with open(os.path.join(d, "compile_commands.json"), "w", encoding="utf-8") as fh:
                json.dump([{"directory": d, "file": "src/node/x/counter.cpp",
                            "command": f"c++ -Isrc -DNDEBUG -O2 -c src/node/x/counter.cpp"}], fh)
            out = io.StringIO()
            with contextlib.redirect_stdout(out):
                bad = check(d, d, 1, clang)
            ok = (not bad) if expect is None else (bool(bad) and expect in out.getvalue())
            if not ok:
                print(out.getvalue().rstrip())
        finally:
            shutil.rmtree(d, ignore_errors=True)
        print(f"   {'ok' if ok else 'FAILED'}: expected {expect or 'no finding'}")
        failed += not ok
    return 1 if failed else 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", nargs="?", default=os.path.join(os.path.dirname(__file__), ".."))
    ap.add_argument("--build", help="the build tree whose compile_commands.json is used")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--clang")
    ap.add_argument("--only", action="append", default=[], metavar="PREFIX")
    ap.add_argument("--self-test", action="store_true")
    a = ap.parse_args()
    clang = find_clang(a.clang)
    if a.self_test:
        if clang is None:
            print("check_thread_safety: no clang++ found (scripts/install-deps.sh installs clang-14)")
            return 1
        return self_test(clang)
    if not a.build:
        ap.error("--build DIR is required")
    root, build = os.path.abspath(a.root), os.path.abspath(a.build)
    return 1 if check(root, build, a.jobs, clang, a.only) else 0


if __name__ == "__main__":
    sys.exit(main())
