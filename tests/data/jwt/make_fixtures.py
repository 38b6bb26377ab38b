#!/usr/bin/env python3
"""Generates the JWT test fixtures in this directory (run once; outputs are committed).

Independent of the C++ code: keys come from pyca/cryptography 48, tokens are assembled
here by hand (base64url JSON header/claims, signatures from cryptography; ES256 converted
from DER to raw r||s as RFC 7518 requires). Run:  python3 make_fixtures.py
Files:
  ed25519_priv.pem / ed25519_pub.pem / ed25519_pub.jwk      EdDSA key (kid "ed-1")
  p256_priv.pem / p256_pub.pem / p256_pub.jwk               ES256 key (kid "ec-1")
  rsa2048_priv.pem / rsa2048_pub.pem / rsa2048_pub.jwk      RS256 key (kid "rsa-1")
  rsa1024_pub.pem                                           too-small RSA key (must be refused)
  p384_pub.pem                                              wrong curve (must be refused)
  jwks.json                                                 the three public JWKs
  hs256.secret                                              48-byte shared secret (text)
  tokens.json                                               tokens + expectations
All tokens are valid from iat 1767225000 until exp 4102444800 (year 2100); tests pin
now = 1767225600 (2026-01-01T00:00:00Z).
"""
import base64, json, os
from cryptography.hazmat.primitives import hashes, hmac, serialization
from cryptography.hazmat.primitives.asymmetric import ec, ed25519, padding, rsa
from cryptography.hazmat.primitives.asymmetric.utils import decode_dss_signature

HERE = os.path.dirname(os.path.abspath(__file__))
ISS = "https://auth.example.org"
AUD = "rcan://continuon.cloud/continuon/companion-v1/*"

def b64u(b): return base64.urlsafe_b64encode(b).rstrip(b"=").decode()
def seg(obj): return b64u(json.dumps(obj, separators=(",", ":")).encode())
def write(name, data, mode="w"):
    with open(os.path.join(HERE, name), mode) as f: f.write(data)

def pem_priv(k): return k.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                        serialization.NoEncryption()).decode()
def pem_pub(k): return k.public_key().public_bytes(serialization.Encoding.PEM,
                                                   serialization.PublicFormat.SubjectPublicKeyInfo).decode()

ed = ed25519.Ed25519PrivateKey.from_private_bytes(bytes(range(32)))
p256 = ec.derive_private_key(0x1234567890abcdef1234567890abcdef1234567890abcdef1234567890abcdef, ec.SECP256R1())
rsa_k = rsa.generate_private_key(public_exponent=65537, key_size=2048)
rsa_small = rsa.generate_private_key(public_exponent=65537, key_size=1024)
p384 = ec.generate_private_key(ec.SECP384R1())
secret = b"rcan-test-hs256-shared-secret-0123456789abcdef!!"  # 48 bytes

write("ed25519_priv.pem", pem_priv(ed)); write("ed25519_pub.pem", pem_pub(ed))
write("p256_priv.pem", pem_priv(p256)); write("p256_pub.pem", pem_pub(p256))
write("rsa2048_priv.pem", pem_priv(rsa_k)); write("rsa2048_pub.pem", pem_pub(rsa_k))
write("rsa1024_pub.pem", pem_pub(rsa_small)); write("p384_pub.pem", pem_pub(p384))
write("hs256.secret", secret.decode())

edx = ed.public_key().public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
jwk_ed = {"kty": "OKP", "crv": "Ed25519", "x": b64u(edx), "kid": "ed-1", "use": "sig", "alg": "EdDSA"}
nums = p256.public_key().public_numbers()
jwk_ec = {"kty": "EC", "crv": "P-256", "x": b64u(nums.x.to_bytes(32, "big")), "y": b64u(nums.y.to_bytes(32, "big")),
          "kid": "ec-1", "alg": "ES256"}
rn = rsa_k.public_key().public_numbers()
jwk_rsa = {"kty": "RSA", "n": b64u(rn.n.to_bytes(256, "big")), "e": b64u(rn.e.to_bytes(3, "big")), "kid": "rsa-1",
           "alg": "RS256"}
write("ed25519_pub.jwk", json.dumps(jwk_ed)); write("p256_pub.jwk", json.dumps(jwk_ec))
write("rsa2048_pub.jwk", json.dumps(jwk_rsa))
write("jwks.json", json.dumps({"keys": [jwk_ed, jwk_ec, jwk_rsa]}, indent=1))

def sign(alg, signing_input):
    m = signing_input.encode()
    if alg == "EdDSA": return ed.sign(m)
    if alg == "ES256":
        r, s = decode_dss_signature(p256.sign(m, ec.ECDSA(hashes.SHA256())))
        return r.to_bytes(32, "big") + s.to_bytes(32, "big")
    if alg == "RS256": return rsa_k.sign(m, padding.PKCS1v15(), hashes.SHA256())
    if alg == "HS256":
        h = hmac.HMAC(secret, hashes.SHA256()); h.update(m); return h.finalize()
    raise ValueError(alg)

def token(alg, claims, kid=None, header_extra=None):
    h = {"alg": alg, "typ": "JWT"}
    if kid: h["kid"] = kid
    if header_extra: h.update(header_extra)
    si = seg(h) + "." + seg(claims)
    return si + "." + b64u(sign(alg, si))

base = {"iss": ISS, "sub": "user-7f3c", "aud": AUD, "role": "owner", "scope": ["control", "config", "training"],
        "fleet": ["d3a4b5c6", "robot-002"], "iat": 1767225000, "exp": 4102444800}
cases = []
for alg, kid in [("EdDSA", "ed-1"), ("ES256", "ec-1"), ("RS256", "rsa-1"), ("HS256", None)]:
    cases.append({"name": "valid_" + alg, "alg": alg, "token": token(alg, base, kid), "valid": True})
# rcan-py numeric role and rcan_scopes; aud array; space-separated scope string
c = dict(base); del c["role"]; del c["scope"]; c["rcan_role"] = 2.5; c["rcan_scopes"] = ["control"]
c["aud"] = ["rcan://other.example/x/y/*", AUD]
cases.append({"name": "rcan_role_2_5_aud_array", "alg": "EdDSA", "token": token("EdDSA", c, "ed-1"), "valid": True,
              "role": "user"})
c = dict(base); c["scope"] = "status chat"
cases.append({"name": "scope_string", "alg": "ES256", "token": token("ES256", c, "ec-1"), "valid": True,
              "scopes": ["status", "chat"]})
# §8.5
c = dict(base); c["sender_type"] = "cloud_function"
cases.append({"name": "cloud_function_without_provider", "alg": "EdDSA", "token": token("EdDSA", c, "ed-1"),
              "valid": False, "reason": "missing_cloud_provider"})
c = dict(base); c["sender_type"] = "cloud_function"; c["cloud_provider"] = "firebase"; c["function_name"] = "castor-bridge-v2"
cases.append({"name": "cloud_function_with_provider", "alg": "EdDSA", "token": token("EdDSA", c, "ed-1"), "valid": True})
c = dict(base); c["exp"] = 1767225000
cases.append({"name": "expired", "alg": "RS256", "token": token("RS256", c, "rsa-1"), "valid": False, "reason": "expired"})
c = dict(base); c["aud"] = "rcan://continuon.cloud/continuon/other-model/*"
cases.append({"name": "wrong_aud", "alg": "RS256", "token": token("RS256", c, "rsa-1"), "valid": False,
              "reason": "aud_mismatch"})
c = dict(base); c["iss"] = "https://evil.example"
cases.append({"name": "unknown_issuer", "alg": "EdDSA", "token": token("EdDSA", c, "ed-1"), "valid": False,
              "reason": "untrusted_issuer"})
# alg none
cases.append({"name": "alg_none", "alg": "none", "token": seg({"alg": "none", "typ": "JWT"}) + "." + seg(base) + ".",
              "valid": False, "reason": "alg_none"})
# algorithm confusion: HS256 keyed with the RSA public key PEM bytes
si = seg({"alg": "HS256", "typ": "JWT", "kid": "rsa-1"}) + "." + seg(base)
h = hmac.HMAC(pem_pub(rsa_k).encode(), hashes.SHA256()); h.update(si.encode())
cases.append({"name": "hs256_with_rsa_public_key", "alg": "HS256", "token": si + "." + b64u(h.finalize()),
              "valid": False, "reason": "alg_mismatch"})
# tampered claims (signature over other bytes)
t = token("ES256", base, "ec-1").split(".")
c = dict(base); c["role"] = "creator"
cases.append({"name": "tampered_claims", "alg": "ES256", "token": t[0] + "." + seg(c) + "." + t[2], "valid": False,
              "reason": "bad_signature"})
write("tokens.json", json.dumps({"issuer": ISS, "robot_ruri": "rcan://continuon.cloud/continuon/companion-v1/d3a4b5c6",
                                 "device_id": "d3a4b5c6", "now": 1767225600, "cases": cases}, indent=1))
print("wrote", len(cases), "tokens")
