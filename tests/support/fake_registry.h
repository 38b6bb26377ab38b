// A registry stand-in for the tests that start rcand with registry.trust_tokens: python3's
// http.server, started by the test, serving the JWKS, the revocation feed and /healthz from
// files the test writes in its root (jwks.json, revocations.json, active.json), and answering
// introspection for the robot key "rk-test". Header-only.
#pragma once

namespace rcan::test {

// The registry's token authority as the contract describes it (GET only: what rcand reads).
inline constexpr const char* kFakeRegistry = R"PY(
import base64, json, os, sys, http.server, urllib.parse
port, root = int(sys.argv[1]), sys.argv[2]
def read(name, default):
    try:
        with open(os.path.join(root, name)) as f:
            return f.read()
    except OSError:
        return default
class H(http.server.BaseHTTPRequestHandler):
    def log_message(self, *a):
        pass
    def send(self, code, body):
        b = body.encode()
        self.send_response(code)
        self.send_header('Content-Type', 'application/json')
        self.send_header('Content-Length', str(len(b)))
        self.end_headers()
        self.wfile.write(b)
    def do_GET(self):
        u = urllib.parse.urlparse(self.path)
        with open(os.path.join(root, 'requests.log'), 'a') as f:
            f.write(u.path + '\n')
        if u.path == '/healthz':
            return self.send(200, '{"status":"ok"}')
        if u.path == '/.well-known/jwks.json':
            return self.send(200, read('jwks.json', '{"keys":[]}'))
        if u.path == '/api/v1/revocations':
            since = int(urllib.parse.parse_qs(u.query).get('since', ['0'])[0])
            revs = [r for r in json.loads(read('revocations.json', '[]')) if r['seq'] > since][:500]
            nxt = revs[-1]['seq'] if revs else since
            return self.send(200, json.dumps({'revocations': revs, 'next_since': nxt}))
        self.send(404, '{}')
    def do_POST(self):
        u = urllib.parse.urlparse(self.path)
        body = self.rfile.read(int(self.headers.get('Content-Length', '0'))).decode()
        with open(os.path.join(root, 'requests.log'), 'a') as f:
            f.write(u.path + '\n')
        if u.path != '/oauth/introspect':
            return self.send(404, '{}')
        if self.headers.get('Authorization') != 'Bearer rk-test' or \
                self.headers.get('Content-Type') != 'application/x-www-form-urlencoded':
            return self.send(401, '{"error":"unauthorized"}')
        tok = urllib.parse.parse_qs(body)['token'][0]
        p = tok.split('.')[1]
        claims = json.loads(base64.urlsafe_b64decode(p + '=' * (-len(p) % 4)))
        if claims.get('jti') not in json.loads(read('active.json', '[]')):
            return self.send(200, '{"active":false}')
        claims['active'] = True
        self.send(200, json.dumps(claims))
http.server.ThreadingHTTPServer.allow_reuse_address = True
s = http.server.ThreadingHTTPServer(('127.0.0.1', port), H)
print('fake registry serving', file=sys.stderr, flush=True)
s.serve_forever()
)PY";

}  // namespace rcan::test
