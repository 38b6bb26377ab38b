"""What the tree checks (scripts/check_*.py) share: a self-test over small trees written to a
temporary directory, and the command line.

  run_self_test(prefix, base, cases, check, fine): writes `base` updated by each case's files,
  runs `check(root)` on it (a list of problems) and passes when a case expecting None finds
  nothing and every other case finds a problem containing its expected text.
"""
import os
import shutil
import sys
import tempfile


def run_self_test(prefix, base, cases, check, fine="no problem"):
    failed = 0
    for name, extra, expect in cases:
        d = tempfile.mkdtemp(prefix=prefix)
        try:
            for path, text in {**base, **extra}.items():
                os.makedirs(os.path.dirname(os.path.join(d, path)), exist_ok=True)
                with open(os.path.join(d, path), "w", encoding="utf-8") as fh:
                    fh.write(text)
            print(f"-- {name}")
            errors = check(d)
        finally:
            shutil.rmtree(d, ignore_errors=True)
        ok = (not errors) if expect is None else any(expect in e for e in errors)
        print(f"   {'ok' if ok else 'FAILED'}: expected {expect or fine}")
        failed += not ok
    return 1 if failed else 0


def main(check, self_test):
    """`script [ROOT]` checks the tree (exit 1 on a problem); `script --self-test` tests the check."""
    if sys.argv[1:] == ["--self-test"]:
        return self_test()
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(sys.argv[0]), "..")
    return 1 if check(os.path.abspath(root)) else 0
