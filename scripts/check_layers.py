#!/usr/bin/env python3
"""The layer rule of docs/ARCHITECTURE.md, checked on the includes of every source file.

Each folder of the project belongs to one layer; a layer may include only from itself and the
layers below it. The check fails on an include that points upwards and on any cycle between
folders (two folders that include each other, directly or around a longer loop), and names
the file, the line and the two layers.

  scripts/check_layers.py [ROOT]      exit 0: the graph follows the rule; 1: it does not
  scripts/check_layers.py --self-test  shows that the check fails on an upward include, a cycle
                                       and a CLI include of the node (in a temporary tree)
"""
import os
import re
import sys

# Bottom to top. A file's layer is the entry with the longest prefix matching its path.
LAYERS = [
    ("base", ["include/rcan/base/", "src/base/"]),  # the bottom: clocks, locks, the file-system Env
    ("core", ["include/rcan/json.h", "include/rcan/result.h", "include/rcan/", "src/core/"]),
    ("crypto", ["include/rcan/crypto/", "src/crypto/"]),
    ("audit", ["include/rcan/audit/", "src/audit/"]),
    ("client", ["include/rcan/client.h", "src/client/"]),
    ("runtime", ["src/runtime/"]),  # log, state files, the data directory, outbound HTTP
    ("transport", ["src/transport/"]),
    ("config", ["src/config/"]),
    ("registry", ["src/registry/"]),
    ("node/safety", ["src/node/safety/"]),
    ("drivers", ["src/drivers/"]),  # hardware drivers under the safety core (driver.h)
    ("node/admission", ["src/node/admission/"]),
    ("node/control", ["src/node/control/"]),
    ("node/services", ["src/node/services/"]),
    ("node/discovery", ["src/node/discovery/"]),
    ("node/pipeline", ["src/node/pipeline/"]),
    ("node/ai", ["src/node/ai/"]),
    ("node/fleet", ["src/node/fleet/"]),
    ("node/api", ["src/node/api/"]),
    ("node/bindings", ["src/node/bindings/"]),
    ("testing", ["src/testing/"]),
    ("apps/rcan", ["apps/rcan/"]),
    ("apps/rcand", ["apps/rcand/"]),
    ("apps/rcan-registry", ["apps/rcan-registry/"]),
]
# Layers that must not reach some lower layers even though they sit above them: the CLI is a
# client of robots, not a robot (it links neither the node nor Boost.Beast).
FORBIDDEN = {
    "apps/rcan": {"runtime", "transport", "config"} | {n for n, _ in LAYERS if n.startswith("node/")},
    "testing": {n for n, _ in LAYERS if n.startswith("node/")} | {"runtime", "transport", "config"},
}
# Only these files of the forbidden layers may be used by the CLI: the MQTT client (its own
# library) and the configuration loader, which `rcan doctor` runs exactly as the node does
# (rcan_config links rcan_runtime and the MQTT client, neither the node nor Boost.Beast).
CLI_ALLOWED = {"src/transport/mqtt_client.h", "src/config/config.h"}
SCANNED = ("include/", "src/", "apps/")
INCLUDE_RE = re.compile(r'^\s*#\s*include\s+"([^"]+)"')


def layer_of(path):
    """(rank, name) of the layer whose prefix matches `path` most closely, or None."""
    best = None
    for rank, (name, prefixes) in enumerate(LAYERS):
        for p in prefixes:
            if path == p or (p.endswith("/") and path.startswith(p)):
                if best is None or len(p) > best[0]:
                    best = (len(p), rank, name)
    return (best[1], best[2]) if best else None


def resolve(root, including, target):
    """The repository path an #include "target" in `including` refers to, or None (system)."""
    candidates = [os.path.join(os.path.dirname(including), target), "src/" + target, "include/" + target]
    for c in candidates:
        c = os.path.normpath(c)
        if os.path.isfile(os.path.join(root, c)):
            return c
    return None


def sources(root):
    for top in SCANNED:
        for dirpath, _, files in os.walk(os.path.join(root, top)):
            for f in files:
                if f.endswith((".h", ".cpp")):
                    yield os.path.relpath(os.path.join(dirpath, f), root)


def folder(path):
    return os.path.dirname(path)


def check(root):
    """The violations found under `root` (printed), and the number of files read."""
    errors = []
    edges = {}  # folder -> {folder: first (file, line)}
    files = sorted(sources(root))
    for path in files:
        own = layer_of(path)
        if own is None:
            errors.append(f"{path}: in no layer (add its folder to scripts/check_layers.py)")
            continue
        with open(os.path.join(root, path), encoding="utf-8", errors="replace") as fh:
            for lineno, line in enumerate(fh, 1):
                m = INCLUDE_RE.match(line)
                if not m:
                    continue
                target = resolve(root, path, m.group(1))
                if target is None:
                    continue  # generated (rcan.pb.h) or a system header in quotes
                other = layer_of(target)
                if other is None:
                    errors.append(f"{path}:{lineno}: includes {target}, which is in no layer")
                    continue
                if folder(target) != folder(path):
                    edges.setdefault(folder(path), {}).setdefault(folder(target), (path, lineno))
                if other[0] > own[0]:
                    errors.append(f"{path}:{lineno}: upward include of {target} "
                                  f"(layer {own[1]} may not include layer {other[1]})")
                elif other[1] in FORBIDDEN.get(own[1], ()) and target not in CLI_ALLOWED:
                    errors.append(f"{path}:{lineno}: layer {own[1]} may not include {target} "
                                  f"(layer {other[1]})")
    # Cycles between folders (also inside one layer, e.g. a folder and its subfolder).
    state, stack = {}, []

    def visit(n):
        state[n] = 1
        stack.append(n)
        for m in sorted(edges.get(n, {})):
            if state.get(m) == 1:
                cyc = stack[stack.index(m):] + [m]
                where = ", ".join("%s -> %s (%s:%d)" % (a, b, *edges[a][b]) for a, b in zip(cyc, cyc[1:]))
                errors.append("cycle between folders: " + where)
            elif m not in state:
                visit(m)
        stack.pop()
        state[n] = 2

    for n in sorted(edges):
        if n not in state:
            visit(n)
    for e in errors:
        print(e)
    print(f"check_layers: {len(files)} files, {sum(len(v) for v in edges.values())} folder edges, "
          f"{len(errors)} violation(s)")
    return errors


def self_test():
    """A small tree that follows the rule, then three ways to break it: each must be caught."""
    import shutil
    import tempfile

    def tree(extra):
        d = tempfile.mkdtemp(prefix="check_layers.")
        made.append(d)
        base = {
            "include/rcan/json.h": "",
            "src/runtime/log.h": '#include "rcan/json.h"\n',
            "src/transport/http_api.h": '#include "runtime/log.h"\n',
            "src/node/pipeline/pipeline.h": '#include "transport/http_api.h"\n',
            "src/node/api/node.h": '#include "node/pipeline/pipeline.h"\n',
            "apps/rcan/main.cpp": '#include "rcan/json.h"\n',
        }
        base.update(extra)
        for path, text in base.items():
            os.makedirs(os.path.dirname(os.path.join(d, path)), exist_ok=True)
            with open(os.path.join(d, path), "a", encoding="utf-8") as fh:
                fh.write(text)
        return d

    cases = [
        ("a tree that follows the rule", {}, None),
        ("an upward include", {"src/transport/http_api.h": '#include "node/api/node.h"\n'}, "upward include"),
        ("a cycle inside one layer", {"src/node/pipeline/sub/x.h": '#include "node/pipeline/pipeline.h"\n',
                                      "src/node/pipeline/pipeline.h": '#include "node/pipeline/sub/x.h"\n'},
         "cycle between folders"),
        ("the CLI including the node", {"apps/rcan/main.cpp": '#include "node/api/node.h"\n'}, "may not include"),
    ]
    failed, made = 0, []
    for name, extra, expect in cases:
        print(f"-- {name}")
        errors = check(tree(extra))
        ok = (not errors) if expect is None else any(expect in e for e in errors)
        print(f"   {'ok' if ok else 'FAILED'}: expected {expect or 'no violation'}")
        failed += not ok
    for d in made:
        shutil.rmtree(d, ignore_errors=True)
    return 1 if failed else 0


def main():
    if sys.argv[1:] == ["--self-test"]:
        return self_test()
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..")
    return 1 if check(os.path.abspath(root)) else 0


if __name__ == "__main__":
    sys.exit(main())
