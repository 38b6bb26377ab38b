#!/usr/bin/env python3
"""The dependency graph of docs/ARCHITECTURE.md, checked on the includes of every source file.

Each folder (sometimes a part of one) is a unit, and each unit declares the units it depends
on (DEPENDS below). A file may include from its own unit and from every unit its unit reaches
through the declared dependencies. The graph itself must hold the architecture's rules: it has
no cycle; librcan (core, crypto, audit) reaches nothing but itself and base; nothing of the node
reaches the registry, nor the other way round. Some units are further held to direct includes
(FORBIDDEN: the CLI, the test doubles). The check also fails on any cycle between the folders
the includes actually join, and it reads tests/, bench/, fuzz/ and examples/ too.

  scripts/check_layers.py [ROOT]          exit 0: the includes follow the graph; 1: they do not
  scripts/check_layers.py --cmake FILE [ROOT]
                                          also checks the link graph CMake wrote
                                          (<build>/generated/layers_cmake.txt) against this one
  scripts/check_layers.py --self-test     shows that the check fails on a forbidden include
                                          (node -> registry, librcan -> node, the CLI -> the
                                          node, an include outside the graph) and on a cycle, in
                                          a temporary tree
"""
import os
import re
import sys

LIBRCAN = {"core", "crypto", "audit"}
PRODUCT = LIBRCAN | {"base", "runtime", "http", "client", "mqtt", "transport", "config", "registry", "registry/api",
                     "node/admission", "node/vocabulary", "node/control", "node/safety", "node/services", "node/discovery",
                     "node/pipeline", "node/ai", "node/fleet", "node/api", "node/bindings", "grpc",
                     "drivers/process", "drivers/ros2", "testing"}
NODE = {u for u in PRODUCT if u.startswith(("node/", "drivers/"))} | {"grpc", "apps/rcand"}
REGISTRY = {"registry", "registry/api", "apps/rcan-registry"}

# unit: (the paths it holds, the units it depends on directly). A path ending in "/" is a
# folder, any other a prefix of file names; a file is in the unit of its longest matching path.
# base is the bottom: every unit may use it without naming it.
UNITS = {
    # librcan (include/rcan, installed)
    "core": (["include/rcan/", "src/core/"], set()),
    "crypto": (["include/rcan/crypto/", "src/crypto/"], {"core"}),
    "audit": (["include/rcan/audit/", "src/audit/"], {"core", "crypto"}),
    "base": (["include/rcan/base/", "src/base/"], set()),
    # the client library (include/rcan/client.h) and its HTTP exchange (rcan_http, also the
    # node's outbound client), which speaks in client.h's types
    "http": (["include/rcan/client.h", "src/client/net.", "src/client/wire."], {"core"}),
    "client": (["src/client/"], {"http", "core"}),
    # what the programs share above librcan: log, state files, the data directory, outbound HTTP
    "runtime": (["src/runtime/"], {"http", "core"}),
    "mqtt": (["src/transport/mqtt_client."], {"core"}),
    "transport": (["src/transport/"], {"runtime", "core"}),
    "config": (["src/config/"], {"runtime", "mqtt", "core", "crypto", "audit"}),
    # the registry
    "registry": (["src/registry/"], {"core"}),
    "registry/api": (["src/registry/api/"], {"registry", "transport", "core", "crypto", "audit"}),
    # the node, from the bottom
    "node/admission": (["src/node/admission/"], {"runtime", "core", "crypto", "audit"}),
    # what every node service speaks (the audit trail, the event bus), under the services
    "node/vocabulary": (["src/node/vocabulary/"], {"node/admission", "runtime", "core", "audit"}),
    "node/safety": (["src/node/safety/"], {"config", "core", "audit"}),
    "node/control": (["src/node/control/"], {"node/admission", "node/vocabulary", "node/safety", "runtime",
                                             "core"}),
    "node/services": (["src/node/services/"], {"node/admission", "node/vocabulary", "node/control",
                                               "node/safety", "transport", "config", "core", "audit"}),
    "node/discovery": (["src/node/discovery/"], {"node/services", "config", "core"}),
    "node/pipeline": (["src/node/pipeline/"], {"node/services", "node/admission", "core"}),
    "node/ai": (["src/node/ai/"], {"node/pipeline", "node/services", "transport", "config", "core", "crypto",
                                   "audit"}),
    "node/fleet": (["src/node/fleet/"], {"node/pipeline", "node/services", "config", "core"}),
    "node/api": (["src/node/api/"], {"node/ai", "node/discovery", "node/fleet", "node/pipeline", "node/services",
                                     "node/admission", "transport", "core", "crypto", "audit"}),
    "node/bindings": (["src/node/bindings/"], {"node/api", "node/fleet", "node/services", "transport", "config",
                                               "core", "crypto"}),
    # gRPC (rcan_grpc, the module librcand_grpc.so): the conversion and the node's binding;
    # the binding's headers (grpc_module.h, grpc_server.h) are the interface rcand loads the
    # module by, in node/bindings.
    "grpc": (["src/transport/grpc_", "src/node/bindings/grpc_server.cpp", "src/node/bindings/grpc_module.cpp"],
             {"node/api", "node/bindings", "transport", "core"}),
    # hardware drivers under the safety core (driver.h)
    "drivers/process": (["src/drivers/process/"], {"node/safety", "core"}),
    "drivers/ros2": (["src/drivers/ros2/"], {"node/safety", "config", "core"}),
    # test doubles (tests and fuzz targets only)
    "testing": (["src/testing/"], {"audit", "core"}),
    # programs
    "apps/rcan": (["apps/rcan/"], {"client", "config", "mqtt", "core", "crypto", "audit"}),
    "apps/rcand": (["apps/rcand/"], {"node/bindings", "node/api", "node/ai", "node/fleet", "node/discovery",
                                     "node/pipeline", "node/services", "node/safety", "node/control",
                                     "node/admission", "drivers/process", "drivers/ros2", "transport", "config",
                                     "core", "crypto", "audit"}),
    "apps/rcan-registry": (["apps/rcan-registry/"], {"registry/api", "registry", "transport", "core", "crypto",
                                                     "audit"}),
    # tests, benchmarks, fuzz targets, examples: they use what they test. A test of librcan
    # stays on librcan; the plain helpers (tests/support) too; the rest may use anything, but no
    # one file both the node and the registry (EXCLUSIVE below).
    "tests/support": (["tests/support/test_support.", "tests/support/audit_util.", "tests/support/postgres.",
                       "tests/support/pty_base.", "tests/support/fake_registry."], {"core", "crypto", "audit"}),
    "tests/librcan": (["tests/core/", "tests/crypto/", "tests/audit/", "tests/cli/"],
                      {"core", "crypto", "audit", "testing", "tests/support"}),
    "tests/fixtures": (["tests/support/"], (PRODUCT - REGISTRY) | {"tests/support"}),
    "tests": (["tests/"], PRODUCT | {"tests/support", "tests/fixtures"}),
    "bench": (["bench/"], PRODUCT | {"tests/fixtures"}),
    "fuzz": (["fuzz/"], PRODUCT),
    "examples": (["examples/"], {"drivers/ros2", "node/safety", "core"}),
}
BOTTOM = "base"
CONSUMERS = {"tests/support", "tests/librcan", "tests/fixtures", "tests", "bench", "fuzz", "examples"}
# What a unit includes beyond its declared dependencies while a move is under way, counted for
# what is reachable through it except from librcan. Empty: base stands on nothing.
TRANSITIONAL = {}
# Units held to their direct includes too, whatever they reach: the CLI is a client of robots,
# not a robot (it links neither the node nor Boost.Beast); the test doubles stand on librcan.
FORBIDDEN = {
    "apps/rcan": {"runtime", "transport", "config"} | {u for u in NODE if u != "apps/rcand"},
    "testing": {u for u in NODE if u != "apps/rcand"} | {"runtime", "transport", "config"},
}
# The only files of those units the CLI uses: the MQTT client (its own library, rcan_mqtt), the
# configuration loader, which `rcan doctor` runs exactly as the node does.
CLI_ALLOWED = {"src/transport/mqtt_client.h", "src/config/config.h"}
# No one file of these units includes both the node and the registry.
EXCLUSIVE = {"tests", "tests/fixtures", "bench", "fuzz"}
SCANNED = ("include/", "src/", "apps/", "tests/", "bench/", "fuzz/", "examples/")
INCLUDE_RE = re.compile(r'^\s*#\s*include\s+"([^"]+)"')


def unit_of(path):
    """The unit whose path matches `path` most closely, or None."""
    best = None
    for name, (paths, _) in UNITS.items():
        for p in paths:
            if path == p or path.startswith(p):
                if best is None or len(p) > best[0]:
                    best = (len(p), name)
    return best[1] if best else None


def reach(unit, transitional=True):
    """The units `unit` may include: itself, base, and everything its dependencies reach."""
    seen, todo = {unit}, [unit]
    transitional = transitional and unit not in LIBRCAN
    while todo:
        u = todo.pop()
        deps = set(UNITS[u][1]) | ({BOTTOM} if u != BOTTOM else set())
        if transitional:
            deps |= TRANSITIONAL.get(u, set())
        for d in deps:
            if d in UNITS and d not in seen:
                seen.add(d)
                todo.append(d)
    return seen


def check_graph():
    """The declared graph's own faults: unknown units, cycles, the architecture's rules."""
    errors = []
    for u, (_, deps) in UNITS.items():
        for d in sorted(set(deps) - set(UNITS)):
            errors.append(f"graph: {u} depends on {d}, which is no unit")
    state = {}

    def visit(u, stack):
        state[u] = 1
        for d in sorted(UNITS[u][1] & set(UNITS)):
            if state.get(d) == 1:
                errors.append("graph: cycle " + " -> ".join(stack[stack.index(d):] + [u, d]))
            elif d not in state:
                visit(d, stack + [u])
        state[u] = 2

    for u in sorted(UNITS):
        if u not in state:
            visit(u, [])
    for u in sorted(UNITS):
        if u in CONSUMERS:
            continue
        r = reach(u, transitional=False)
        if u in LIBRCAN and r - LIBRCAN - {BOTTOM}:
            errors.append(f"graph: librcan's {u} reaches {sorted(r - LIBRCAN - {BOTTOM})}")
        if u in NODE and r & REGISTRY:
            errors.append(f"graph: the node's {u} reaches the registry's {sorted(r & REGISTRY)}")
        if u in REGISTRY and r & NODE:
            errors.append(f"graph: the registry's {u} reaches the node's {sorted(r & NODE)}")
    return errors


def resolve(root, including, target):
    """The repository path an #include "target" in `including` refers to, or None (system)."""
    candidates = [os.path.join(os.path.dirname(including), target), "src/" + target, "include/" + target,
                  "tests/support/" + target]
    for c in candidates:
        c = os.path.normpath(c)
        if os.path.isfile(os.path.join(root, c)):
            return c
    return None


def sources(root):
    for top in SCANNED:
        for dirpath, _, files in os.walk(os.path.join(root, top)):
            if "node_modules" in dirpath:
                continue
            for f in files:
                if f.endswith((".h", ".cpp", ".inc")):
                    yield os.path.relpath(os.path.join(dirpath, f), root)


def check_includes(root):
    """The include violations under `root`, the folder edges, and the number of files read."""
    errors = []
    edges = {}  # folder -> {folder: first (file, line)}
    reaches = {u: reach(u) for u in UNITS}
    files = sorted(sources(root))
    for path in files:
        own = unit_of(path)
        if own is None:
            errors.append(f"{path}: in no unit (add its folder to scripts/check_layers.py)")
            continue
        families = {}
        with open(os.path.join(root, path), encoding="utf-8", errors="replace") as fh:
            for lineno, line in enumerate(fh, 1):
                m = INCLUDE_RE.match(line)
                if not m:
                    continue
                target = resolve(root, path, m.group(1))
                if target is None:
                    continue  # generated (rcan.pb.h) or a system header in quotes
                other = unit_of(target)
                if other is None:
                    errors.append(f"{path}:{lineno}: includes {target}, which is in no unit")
                    continue
                if os.path.dirname(target) != os.path.dirname(path):
                    edges.setdefault(os.path.dirname(path), {}).setdefault(os.path.dirname(target), (path, lineno))
                if other not in reaches[own]:
                    errors.append(f"{path}:{lineno}: {own} may not include {target} ({other} is not among "
                                  f"the units {own} depends on)")
                elif other in FORBIDDEN.get(own, ()) and target not in CLI_ALLOWED:
                    errors.append(f"{path}:{lineno}: {own} may not include {target} ({other})")
                for fam, members in (("node", NODE), ("registry", REGISTRY)):
                    if other in members:
                        families.setdefault(fam, (target, lineno))
        if own in EXCLUSIVE and len(families) == 2:
            errors.append(f"{path}: includes both the node ({families['node'][0]}) and the registry "
                          f"({families['registry'][0]})")
    # Cycles between folders (also inside one unit, e.g. a folder and its subfolder).
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
    return errors, edges, len(files)


def check_cmake(path):
    """The CMake link graph (cmake/RcanSources.cmake writes it) against the declared graph: each
    link must be one the graph allows, and each declared dependency between two libraries must
    be linked."""
    errors = []
    targets = {}
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            name, srcs, deps = (line.rstrip("\n").split("\t") + ["", ""])[:3]
            units = {unit_of(s) for s in srcs.split()} - {None}
            targets[name] = (units, set(deps.split()))

    def linked(t, seen=None):
        """The targets `t` links, directly or not (libraries without sources of their own are
        passed through)."""
        seen = set() if seen is None else seen
        for d in targets.get(t, (set(), set()))[1]:
            if d in targets and d not in seen:
                seen.add(d)
                linked(d, seen)
        return seen

    for t, (units, _) in sorted(targets.items()):
        if not units:
            continue
        allowed = set().union(*(reach(u) for u in units))
        for d in sorted(linked(t)):
            if targets[d][0] and not targets[d][0] & allowed:
                errors.append(f"cmake: {t} links {d} ({', '.join(sorted(targets[d][0]))}), which "
                              f"{', '.join(sorted(units))} may not use")
    holders = {}
    for t, (units, _) in targets.items():
        for u in units:
            holders.setdefault(u, set()).add(t)
    for u, (_, deps) in sorted(UNITS.items()):
        if u in CONSUMERS or u not in holders:
            continue
        for d in sorted(deps):
            if d not in holders or holders[u] & holders[d]:
                continue
            if not any(linked(t) & holders[d] for t in holders[u]):
                errors.append(f"cmake: {u} depends on {d}, but {', '.join(sorted(holders[u]))} links none of "
                              f"{', '.join(sorted(holders[d]))}")
    return errors, len(targets)


def check(root, cmake=None):
    errors = check_graph()
    include_errors, edges, nfiles = check_includes(root)
    errors += include_errors
    summary = (f"check_layers: {nfiles} files, {len(UNITS)} units, "
               f"{sum(len(v) for v in edges.values())} folder edges")
    if cmake:
        cmake_errors, ntargets = check_cmake(cmake)
        errors += cmake_errors
        summary += f", {ntargets} CMake targets"
    for e in errors:
        print(e)
    print(f"{summary}, {len(errors)} violation(s)")
    return errors


def self_test():
    """A small tree that follows the graph, then ways to break it: each must be caught."""
    import shutil
    import tempfile

    def tree(extra):
        d = tempfile.mkdtemp(prefix="check_layers.")
        made.append(d)
        files = {
            "include/rcan/json.h": "",
            "src/base/clock.h": "",
            "src/runtime/log.h": '#include "rcan/json.h"\n',
            "src/transport/http_api.h": '#include "runtime/log.h"\n#include "rcan/json.h"\n',
            "src/node/services/node_services.h": '#include "transport/http_api.h"\n',
            "src/node/pipeline/pipeline.h": '#include "node/services/node_services.h"\n',
            "src/node/api/node.h": '#include "node/pipeline/pipeline.h"\n',
            "src/registry/store.h": '#include "rcan/json.h"\n',
            "src/registry/api/registry_api.h": '#include "registry/store.h"\n#include "transport/http_api.h"\n',
            "src/core/json.cpp": '#include "rcan/json.h"\n#include "base/clock.h"\n',
            "apps/rcan/main.cpp": '#include "rcan/json.h"\n',
            "tests/node/node_test.cpp": '#include "node/api/node.h"\n',
            "tests/registry/api_test.cpp": '#include "registry/api/registry_api.h"\n',
        }
        files.update(extra)
        for path, text in files.items():
            os.makedirs(os.path.dirname(os.path.join(d, path)), exist_ok=True)
            with open(os.path.join(d, path), "w", encoding="utf-8") as fh:
                fh.write(text)
        return d

    cases = [
        ("a tree that follows the graph", {}, None),
        ("the node including the registry",
         {"src/node/pipeline/pipeline.h": '#include "registry/store.h"\n'}, "node/pipeline may not include"),
        ("the registry including the node",
         {"src/registry/api/registry_api.h": '#include "node/api/node.h"\n'}, "registry/api may not include"),
        ("librcan including the node", {"src/core/json.cpp": '#include "node/api/node.h"\n'},
         "core may not include"),
        ("librcan including the client",
         {"src/core/json.cpp": '#include "client/net.h"\n', "src/client/net.h": ""}, "core may not include"),
        ("an include against the graph (downwards is fine, upwards is not)",
         {"src/transport/http_api.h": '#include "node/api/node.h"\n'}, "transport may not include"),
        ("a cycle inside one unit", {"src/node/pipeline/sub/x.h": '#include "node/pipeline/pipeline.h"\n',
                                     "src/node/pipeline/pipeline.h": '#include "node/pipeline/sub/x.h"\n'},
         "cycle between folders"),
        ("the CLI including the node", {"apps/rcan/main.cpp": '#include "node/api/node.h"\n'}, "may not include"),
        ("the CLI including runtime (which it reaches through config)",
         {"apps/rcan/main.cpp": '#include "runtime/log.h"\n'}, "apps/rcan may not include src/runtime/log.h (runtime)"),
        ("librcan including runtime (which stands on librcan)",
         {"src/core/json.cpp": '#include "runtime/log.h"\n'}, "core may not include src/runtime/log.h"),
        ("a test of librcan including the node", {"tests/core/json_test.cpp": '#include "node/api/node.h"\n'},
         "tests/librcan may not include"),
        ("a fuzz target including both the node and the registry",
         {"fuzz/both_fuzz.cpp": '#include "node/api/node.h"\n#include "registry/store.h"\n'},
         "includes both the node"),
    ]
    failed, made = 0, []
    for name, extra, expect in cases:
        print(f"-- {name}")
        errors = check(tree(extra))
        ok = (not errors) if expect is None else any(expect in e for e in errors)
        print(f"   {'ok' if ok else 'FAILED'}: expected {expect or 'no violation'}")
        failed += not ok
    # The graph's own rules, on a declared dependency planted in a copy of the table.
    graph_cases = [
        ("the graph as it is", None, None, None),
        ("a declared node -> registry", "node/pipeline", "registry", "reaches the registry"),
        ("a declared registry -> node", "registry/api", "node/safety", "reaches the node"),
        ("a declared librcan -> node", "crypto", "node/api", "librcan's crypto reaches"),
        ("a declared cycle", "core", "audit", "graph: cycle"),
    ]
    for name, unit, dep, expect in graph_cases:
        print(f"-- {name}")
        saved = UNITS.get(unit)
        if unit:
            UNITS[unit] = (saved[0], saved[1] | {dep})
        errors = check_graph()
        if unit:
            UNITS[unit] = saved
        for e in errors:
            print(e)
        ok = (not errors) if expect is None else any(expect in e for e in errors)
        print(f"   {'ok' if ok else 'FAILED'}: expected {expect or 'no fault in the graph'}")
        failed += not ok
    for d in made:
        shutil.rmtree(d, ignore_errors=True)
    return 1 if failed else 0


def main():
    args = sys.argv[1:]
    if args == ["--self-test"]:
        return self_test()
    cmake = None
    if args[:1] == ["--cmake"]:
        cmake, args = args[1], args[2:]
    root = args[0] if args else os.path.join(os.path.dirname(__file__), "..")
    return 1 if check(os.path.abspath(root), cmake) else 0


if __name__ == "__main__":
    sys.exit(main())
