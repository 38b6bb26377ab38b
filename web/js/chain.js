// Client-side check of the audit chain's links (docs/AUDIT.md): every record's prev_hash must
// be the SHA-256 of the previous record's canonical JSON without `hmac`, and seq must count up
// by one. The stored JSONL line *is* the canonical JSON, so the pre-image is the line with its
// top-level "hmac" member cut out — no re-serialisation, no float formatting questions.
// The HMACs need the chain secret, which never leaves the robot: `rcan audit verify` checks them.

const K = new Uint32Array([
  0x428a2f98, 0x71374491, 0xb5c0fbcf, 0xe9b5dba5, 0x3956c25b, 0x59f111f1, 0x923f82a4, 0xab1c5ed5,
  0xd807aa98, 0x12835b01, 0x243185be, 0x550c7dc3, 0x72be5d74, 0x80deb1fe, 0x9bdc06a7, 0xc19bf174,
  0xe49b69c1, 0xefbe4786, 0x0fc19dc6, 0x240ca1cc, 0x2de92c6f, 0x4a7484aa, 0x5cb0a9dc, 0x76f988da,
  0x983e5152, 0xa831c66d, 0xb00327c8, 0xbf597fc7, 0xc6e00bf3, 0xd5a79147, 0x06ca6351, 0x14292967,
  0x27b70a85, 0x2e1b2138, 0x4d2c6dfc, 0x53380d13, 0x650a7354, 0x766a0abb, 0x81c2c92e, 0x92722c85,
  0xa2bfe8a1, 0xa81a664b, 0xc24b8b70, 0xc76c51a3, 0xd192e819, 0xd6990624, 0xf40e3585, 0x106aa070,
  0x19a4c116, 0x1e376c08, 0x2748774c, 0x34b0bcb5, 0x391c0cb3, 0x4ed8aa4a, 0x5b9cca4f, 0x682e6ff3,
  0x748f82ee, 0x78a5636f, 0x84c87814, 0x8cc70208, 0x90befffa, 0xa4506ceb, 0xbef9a3f7, 0xc67178f2,
]);

// SHA-256 (FIPS 180-4) of bytes → lower-case hex. Used where WebCrypto is unavailable (a plain
// http:// page on the LAN is not a secure context).
export function sha256Hex(bytes) {
  const h = new Uint32Array([0x6a09e667, 0xbb67ae85, 0x3c6ef372, 0xa54ff53a,
    0x510e527f, 0x9b05688c, 0x1f83d9ab, 0x5be0cd19]);
  const len = bytes.length;
  const padded = new Uint8Array(((len + 9 + 63) >> 6) << 6);
  padded.set(bytes);
  padded[len] = 0x80;
  const view = new DataView(padded.buffer);
  view.setUint32(padded.length - 8, Math.floor(len / 0x20000000));
  view.setUint32(padded.length - 4, (len << 3) >>> 0);
  const w = new Uint32Array(64);
  const rotr = (x, n) => (x >>> n) | (x << (32 - n));
  for (let off = 0; off < padded.length; off += 64) {
    for (let i = 0; i < 16; i++) w[i] = view.getUint32(off + i * 4);
    for (let i = 16; i < 64; i++) {
      const s0 = rotr(w[i - 15], 7) ^ rotr(w[i - 15], 18) ^ (w[i - 15] >>> 3);
      const s1 = rotr(w[i - 2], 17) ^ rotr(w[i - 2], 19) ^ (w[i - 2] >>> 10);
      w[i] = (w[i - 16] + s0 + w[i - 7] + s1) >>> 0;
    }
    let [a, b, c, d, e, f, g, hh] = h;
    for (let i = 0; i < 64; i++) {
      const S1 = rotr(e, 6) ^ rotr(e, 11) ^ rotr(e, 25);
      const ch = (e & f) ^ (~e & g);
      const t1 = (hh + S1 + ch + K[i] + w[i]) >>> 0;
      const S0 = rotr(a, 2) ^ rotr(a, 13) ^ rotr(a, 22);
      const maj = (a & b) ^ (a & c) ^ (b & c);
      const t2 = (S0 + maj) >>> 0;
      hh = g; g = f; f = e; e = (d + t1) >>> 0;
      d = c; c = b; b = a; a = (t1 + t2) >>> 0;
    }
    h[0] += a; h[1] += b; h[2] += c; h[3] += d; h[4] += e; h[5] += f; h[6] += g; h[7] += hh;
  }
  return Array.from(h, (x) => x.toString(16).padStart(8, '0')).join('');
}

// The canonical line without its top-level "hmac" member, or null when the line has none.
// Walks the text once, tracking strings and nesting, so an "hmac" inside a string or a
// nested object is never touched.
export function preimage(line) {
  let depth = 0;
  let inStr = false;
  let esc = false;
  let keyStart = -1;
  for (let i = 0; i < line.length; i++) {
    const c = line[i];
    if (inStr) {
      if (esc) esc = false;
      else if (c === '\\') esc = true;
      else if (c === '"') {
        inStr = false;
        if (depth === 1 && keyStart >= 0 && line[i + 1] === ':' && line.slice(keyStart, i + 1) === '"hmac"') {
          // Value: a string (or null). Find its end.
          let j = i + 2;
          if (line[j] === '"') {
            j++;
            while (j < line.length && line[j] !== '"') { if (line[j] === '\\') j++; j++; }
            j++;
          } else if (line.startsWith('null', j)) {
            j += 4;
          } else {
            return null;
          }
          const before = line[keyStart - 1];
          if (before === ',') return line.slice(0, keyStart - 1) + line.slice(j);
          if (line[j] === ',') return line.slice(0, keyStart) + line.slice(j + 1);
          return line.slice(0, keyStart) + line.slice(j);
        }
      }
      continue;
    }
    if (c === '"') {
      inStr = true;
      const prev = line[i - 1];
      keyStart = depth === 1 && (prev === '{' || prev === ',') ? i : -1;
    } else if (c === '{' || c === '[') depth++;
    else if (c === '}' || c === ']') depth--;
  }
  return null;
}

const enc = new TextEncoder();

// Checks the links of a JSONL export. Returns {checked, firstSeq, lastSeq, intactUpTo, breakAt,
// reason}: the chain is intact from firstSeq to intactUpTo; breakAt names the first record
// whose link does not hold (null when none).
export function verifyLinks(text) {
  const lines = text.split('\n').filter((l) => l.trim() !== '');
  const out = { checked: 0, firstSeq: null, lastSeq: null, intactUpTo: null, breakAt: null, reason: '' };
  let prevHash = null;
  let prevSeq = null;
  for (const line of lines) {
    let rec;
    try { rec = JSON.parse(line); } catch (_) {
      out.breakAt = prevSeq === null ? 1 : prevSeq + 1;
      out.reason = 'a line is not JSON';
      return out;
    }
    const seq = rec.seq;
    if (out.firstSeq === null) out.firstSeq = seq;
    if (prevSeq !== null) {
      if (seq !== prevSeq + 1) {
        out.breakAt = seq;
        out.reason = `seq jumps from ${prevSeq} to ${seq}`;
        return out;
      }
      if (rec.prev_hash !== prevHash) {
        out.breakAt = seq;
        out.reason = 'prev_hash does not hash the previous record';
        return out;
      }
    }
    const pre = preimage(line);
    if (pre === null) {
      out.breakAt = seq;
      out.reason = 'the record has no hmac';
      return out;
    }
    prevHash = sha256Hex(enc.encode(pre));
    prevSeq = seq;
    out.checked += 1;
    out.lastSeq = seq;
    out.intactUpTo = seq;
  }
  return out;
}
