"""rcan-py 3.4.1 (third_party/rcan-py) as a real client of a live rcan-registry (docs/REGISTRY.md).

NodeClient (urllib): manifest, verify_node (an http:// api_base fails it, --public-url https://…
passes), nodes, discover, resolve; the manifest's Ed25519 signature checked with `cryptography`.
RegistryClient needs httpx: register/get/list/search/update run through it. scripts/install-deps.sh
installs Debian's python3-httpx; a python3 without httpx of its own (a pyenv build) takes that
one, pure Python, from Debian's dist-packages, after its own packages. No httpx at all is a
failure, not a skip.

With RCAN_REGISTRY_DATABASE (scripts/with_postgres.sh sets it) the registry the clients work
against runs on that database (PostgreSQL), and the federation's two nodes and the https://
instance on RCAN_REGISTRY_DATABASE_2…_4: every check runs on SQLite and on PostgreSQL.

Exit 0 pass, 1 fail, 77 skip (CTest SKIP_RETURN_CODE): RCAN_REGISTRY_PATH missing.
"""
import base64
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request

SKIP = 77
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(HERE)), "third_party", "rcan-py"))
REGISTRY = os.environ.get("RCAN_REGISTRY_PATH", "")
if not os.path.isfile(REGISTRY):
    print("SKIP: RCAN_REGISTRY_PATH does not name rcan-registry")
    sys.exit(SKIP)

from rcan.exceptions import RCANNodeError  # noqa: E402
from rcan.node import NodeClient  # noqa: E402

failures = []


def check(cond, what):
    print(("ok   " if cond else "FAIL ") + what)
    if not cond:
        failures.append(what)


class Registry:
    def __init__(self, *extra):
        self.dir = tempfile.mkdtemp(prefix="rcan-registry-sdk-")
        self.proc = subprocess.Popen(
            [REGISTRY, "--data-dir", self.dir, "--port", "0", *extra],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        deadline = time.time() + 30
        self.url = None
        while time.time() < deadline:
            line = self.proc.stderr.readline()
            if not line:
                break
            if '"event":"listening"' in line:
                self.url = json.loads(line)["url"]
                break
        if self.url is None:
            raise RuntimeError("rcan-registry did not start")
        with open(os.path.join(self.dir, "admin.key")) as f:
            self.admin = f.read()

    def call(self, method, path, body=None, key=None):
        data = json.dumps(body).encode() if body is not None else None
        req = urllib.request.Request(self.url + path, data=data, method=method)
        req.add_header("Content-Type", "application/json")
        if key:
            req.add_header("Authorization", "Bearer " + key)
        try:
            with urllib.request.urlopen(req, timeout=10) as r:
                return r.status, json.loads(r.read())
        except urllib.error.HTTPError as e:
            return e.code, json.loads(e.read() or b"{}")

    def stop(self):
        self.proc.send_signal(signal.SIGTERM)
        self.proc.wait(timeout=10)
        shutil.rmtree(self.dir, ignore_errors=True)


def b64url(s):
    return base64.urlsafe_b64decode(s + "=" * (-len(s) % 4))


def node_client_checks(reg):
    status, created = reg.call("POST", "/api/v1/robots", {
        "manufacturer": "acme", "model": "arm", "version": "v2", "device_id": "py-1",
        "metadata": {"dof": 6}}, reg.admin)
    check(status == 201, f"register over HTTP → 201 ({status})")
    rrn = created["rrn"]
    nc = NodeClient(root_url=reg.url, timeout=5)
    manifest = nc.get_node_manifest(reg.url)
    check(manifest["node_type"] == "root", "NodeClient.get_node_manifest: root node")
    check(manifest["public_key"].startswith("ed25519:"), "manifest public_key is ed25519:…")
    check(nc.verify_node(manifest) is False, "verify_node refuses an http:// api_base")
    nodes = nc.list_nodes()
    check(len(nodes) == 1 and nodes[0]["node_type"] == "root", "NodeClient.list_nodes")
    resolved = nc.resolve(rrn)
    check(resolved["record"]["rrn"] == rrn, "NodeClient.resolve → the record")
    check(resolved["record"]["metadata"] == {"dof": 6}, "resolve carries the metadata")
    check(nc.discover(rrn)["api_base"] == reg.url + "/api/v1", "NodeClient.discover (root RRN)")
    try:
        nc.resolve("RRN-000000000999")
        check(False, "NodeClient.resolve of an unknown RRN raises")
    except RCANNodeError:
        check(True, "NodeClient.resolve of an unknown RRN raises RCANNodeError")
    status, _ = reg.call("POST", "/api/v1/nodes", {
        "prefix": "BD", "operator": "BD robots", "node_url": "https://bd.example"}, reg.admin)
    check(status == 201, "delegate BD → 201")
    bd = nc.discover("RRN-BD-00000001")
    check(bd.get("namespace_prefix") == "BD" and bd.get("api_base") == "https://bd.example/api/v1",
          "NodeClient.discover finds the delegated node")
    return rrn


def verify_signature(manifest):
    try:
        from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey
    except ImportError:
        print("skip manifest signature check: python3 has no cryptography")
        return
    unsigned = {k: v for k, v in manifest.items() if k != "signature"}
    canonical = json.dumps(unsigned, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
    key = Ed25519PublicKey.from_public_bytes(b64url(manifest["ed25519_public_key"]))
    try:
        key.verify(b64url(manifest["signature"]), canonical.encode())
        check(True, "manifest signature verifies (Ed25519 over canonical JSON)")
    except Exception as e:  # noqa: BLE001
        check(False, f"manifest signature verifies: {e}")


def registry_client_checks(reg):
    try:
        import httpx  # noqa: F401
    except ImportError:
        debian = os.path.join(os.sep, "usr", "lib", "python3", "dist-packages")  # python3-httpx
        if os.path.isdir(os.path.join(debian, "httpx")):
            sys.path.append(debian)  # after this python's own packages: theirs win
        try:
            import httpx  # noqa: F401,F811
        except ImportError as e:
            check(False, f"RegistryClient needs httpx (scripts/install-deps.sh installs python3-httpx): {e}")
            return
    print(f"RegistryClient over httpx {httpx.__version__}")
    import asyncio

    from rcan.registry import RegistryClient

    async def run():
        async with RegistryClient(api_key=reg.admin, base_url=reg.url) as rc:
            r = await rc.register(manufacturer="acme", model="arm", version="v3", device_id="rc-1",
                                  metadata={"k": 1})
            check(r["rrn"].startswith("RRN-"), "RegistryClient.register")
            e = await rc.get_robot(r["rrn"])
            check(e.rrn == r["rrn"] and e.uri is not None, "RegistryClient.get_robot")
            page = await rc.list_robots(manufacturer="acme", per_page=1)
            check(page.total >= 2 and len(page) == 1, "RegistryClient.list_robots (meta)")
            found = await rc.search(model="arm")
            check(len(found) >= 2, "RegistryClient.search")
        async with RegistryClient(api_key=r["api_key"], base_url=reg.url) as rc:
            u = await rc.update(r["rrn"], {"description": "from rcan-py"})
            check(u["description"] == "from rcan-py", "RegistryClient.update with the robot key")

    asyncio.run(run())


def on_database(suffix=""):
    """--database URL for one registry instance when the test runs on PostgreSQL."""
    url = os.environ.get("RCAN_REGISTRY_DATABASE" + suffix, "")
    return ["--database", url] if url else []


def federation_checks():
    """A root node delegating BD to a second rcan-registry (--prefix BD): NodeClient.resolve at
    the root follows the root's 307 to the authoritative node."""
    bd = Registry("--prefix", "BD", *on_database("_2"))
    root = Registry("--allow-http-node-urls", *on_database("_3"))
    try:
        status, made = bd.call("POST", "/api/v1/robots", {
            "manufacturer": "bd", "model": "spot", "version": "v1", "device_id": "f-1"}, bd.admin)
        check(status == 201 and made["rrn"].startswith("RRN-BD-"), "the BD node mints RRN-BD-…")
        status, _ = root.call("POST", "/api/v1/nodes", {
            "prefix": "BD", "operator": "BD robots", "node_url": bd.url}, root.admin)
        check(status == 201, "the root delegates BD to the second node")
        nc = NodeClient(root_url=root.url, timeout=5)
        res = nc.resolve(made["rrn"])
        check(res.get("resolved_by") == bd.url and res["record"]["rrn"] == made["rrn"],
              "NodeClient.resolve at the root follows federation to the BD node")
        check(nc.discover(made["rrn"])["node_url"] == bd.url, "NodeClient.discover → the BD node")
        try:
            nc.resolve("RRN-BD-000000000999")
            check(False, "an unknown RRN-BD-… raises")
        except RCANNodeError:
            check(True, "an unknown RRN-BD-… raises RCANNodeError (root, then the BD node)")
    finally:
        root.stop()
        bd.stop()


def main():
    federation_checks()
    database = os.environ.get("RCAN_REGISTRY_DATABASE", "")
    reg = Registry(*on_database())
    print("registry database: " + (database.split("@")[0] + "@…" if database else "SQLite"))
    try:
        node_client_checks(reg)
        registry_client_checks(reg)
    finally:
        reg.stop()
    secure = Registry("--public-url", "https://registry.example", *on_database("_4"))
    try:
        nc = NodeClient(root_url=secure.url, timeout=5)
        manifest = nc.get_node_manifest(secure.url)
        check(manifest["api_base"] == "https://registry.example/api/v1", "api_base from --public-url")
        check(nc.verify_node(manifest) is True, "verify_node passes with --public-url https://…")
        verify_signature(manifest)
        status, created = secure.call("POST", "/api/v1/robots", {
            "manufacturer": "acme", "model": "arm", "version": "v2", "device_id": "s-1"},
            secure.admin)
        check(re.match(r"^rcan://registry\.example/", created.get("rcan_uri", "")) is not None,
              "rcan:// host from the public URL")
        check(nc.resolve(created["rrn"])["rrn"] == created["rrn"], "resolve on the https node")
    finally:
        secure.stop()
    print(f"{len(failures)} failure(s)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
