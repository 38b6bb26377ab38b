#!/usr/bin/env python3
"""One definition per name in a test program (docs/TESTING.md "The test programs").

Every folder of tests/ builds one program from all its sources, with the shared helpers of
tests/support/ and the folders' own headers. A class defined twice under one qualified name —
two headers, or a header and a source outside an anonymous namespace — is not a link error: the
linker keeps one copy of each inline member function, and one test then runs the other's code.
This check finds such names before they do:

  - a class or struct defined at namespace scope in two files under tests/ or src/testing/ with
    the same namespace (an anonymous namespace makes a name private to its file: ignored);
  - a GoogleTest suite name used by two sources of one folder (a CTest test selects its suite by
    name, so it would run both).

  scripts/check_test_names.py [ROOT]       exit 0: none; 1: the names and their files
  scripts/check_test_names.py --self-test   shows that both cases fail (in a temporary tree)
"""
import os
import re
import sys
from collections import defaultdict

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import check_tree  # noqa: E402  (scripts/check_tree.py)
from check_sizes import strip_code  # noqa: E402  (comments and strings blanked)

SCANNED = ("tests/", "src/testing/")
TOKEN = re.compile(r"namespace\s+([\w:]*)\s*\{|\{|\}")
TYPE_HEAD = re.compile(r"(?:^|[;{}])\s*(?:template\s*<[^;{}]*>\s*)?(?:class|struct)\s+(\w+)"
                       r"(?:\s+final)?\s*(?::[^;{}]*)?$")
SUITE = re.compile(r"^\s*(?:TYPED_TEST_P|TYPED_TEST|TEST_P|TEST_F|TEST)\(\s*(\w+)", re.M)


def types_defined(text):
    """(namespace, name) of each class or struct defined at namespace scope outside an anonymous
    namespace."""
    code = strip_code(text)
    stack, found, last = [], [], 0
    for m in TOKEN.finditer(code):
        head = code[last:m.start()]
        last = m.end()
        if m.group(0) == "}":
            if stack:
                stack.pop()
            continue
        if m.group(0).startswith("namespace"):
            stack.append(("ns", m.group(1)))
            continue
        at_namespace_scope = all(kind == "ns" for kind, _ in stack)
        anonymous = any(kind == "ns" and not name for kind, name in stack)
        t = TYPE_HEAD.search(head.strip())
        if at_namespace_scope and not anonymous and t:
            found.append(("::".join(name for _, name in stack), t.group(1)))
        stack.append(("block", ""))
    return found


def check(root):
    problems = []
    where = defaultdict(set)
    suites = defaultdict(lambda: defaultdict(set))
    for top in SCANNED:
        for dirpath, _, files in os.walk(os.path.join(root, top)):
            for f in sorted(files):
                if not f.endswith((".h", ".cpp")):
                    continue
                path = os.path.join(dirpath, f)
                rel = os.path.relpath(path, root)
                with open(path, encoding="utf-8", errors="replace") as fh:
                    text = fh.read()
                for key in types_defined(text):
                    where[key].add(rel)
                if f.endswith("_test.cpp"):
                    for s in set(SUITE.findall(strip_code(text))):
                        suites[os.path.dirname(rel)][s].add(rel)
    for (ns, name), files in sorted(where.items()):
        if len(files) > 1:
            problems.append(f"class {ns + '::' if ns else ''}{name} is defined in "
                            f"{', '.join(sorted(files))}: one program may hold both")
    for folder, names in sorted(suites.items()):
        for s, files in sorted(names.items()):
            if len(files) > 1:
                problems.append(f"suite {s} is used by {', '.join(sorted(files))}: one CTest test "
                                f"would run both")
    for p in problems:
        print(p)
    print(f"check_test_names: {len(where)} classes, {len(problems)} problems")
    return problems


def self_test():
    helper = "namespace rcan::test {\nclass Node {\n int f() { return 1; }\n};\n}\n"
    base = {
        "tests/support/a.h": helper,
        "tests/e2e/x_test.cpp": "namespace rcan {\nnamespace {\nclass Node {};\n}\n}\n"
                                "TEST(XSuite, A) {}\n",
        "tests/e2e/y_test.cpp": "TEST(YSuite, A) {}\n",
    }
    cases = [
        ("the tree as it should be", {}, None),
        ("one class in two headers", {"tests/support/b.h": helper}, "class rcan::test::Node"),
        ("one suite in two sources", {"tests/e2e/y_test.cpp": "TEST(XSuite, B) {}\n"},
         "suite XSuite"),
    ]
    return check_tree.run_self_test("check_test_names_", base, cases, check)


if __name__ == "__main__":
    sys.exit(check_tree.main(check, self_test))
