# Side-by-side PNG of EXR pairs (the README's docs/cycles-vs-subfield-2.png), with the
# system python3 (OpenEXR + numpy).
# run: python3 benches/side_by_side.py OUT.png BITS LEFT.exr,RIGHT.exr,EV [...]
# Each pair is one row, left | right, 4 px black gaps. RGB × 2^EV (the same EV for both
# images of a row), clamped to [0,1], sRGB-encoded, 8-bit; BITS < 8 posterizes (fewer
# levels a channel) so that the PNG stays small. Each PNG row gets the filter (0-4) with
# the smallest sum of absolute bytes.
import sys, zlib, struct, OpenEXR, Imath, numpy as np
def load(p, ev):
    f = OpenEXR.InputFile(p); dw = f.header()['dataWindow']
    w, h = dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1
    img = np.stack([np.frombuffer(f.channel(c, Imath.PixelType(Imath.PixelType.FLOAT)), np.float32).reshape(h, w) for c in "RGB"], -1)
    img = np.clip(np.nan_to_num(img * 2.0 ** ev), 0, 1)
    return np.where(img <= 0.0031308, img * 12.92, 1.055 * img ** (1 / 2.4) - 0.055)
out, bits = sys.argv[1], int(sys.argv[2])
rows = []
for r in sys.argv[3:]:
    a, b, ev = r.split(","); A, B = load(a, float(ev)), load(b, float(ev))
    rows.append(np.concatenate([A, np.zeros((A.shape[0], 4, 3)), B], 1))
gap = np.zeros((4, rows[0].shape[1], 3))
img = np.concatenate(sum(([r, gap] for r in rows), [])[:-1], 0)
q = (1 << bits) - 1
b8 = (np.round(img * q) / q * 255 + 0.5).astype(np.uint8)
h, w, _ = b8.shape
x = b8.reshape(h, w * 3).astype(np.int16)
a = np.zeros_like(x); a[:, 3:] = x[:, :-3]          # left
b = np.zeros_like(x); b[1:] = x[:-1]                 # up
c = np.zeros_like(x); c[1:, 3:] = x[:-1, :-3]        # up-left
p = a + b - c; pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
paeth = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
cands = [x, x - a, x - b, x - (a + b) // 2, x - paeth]   # PNG filters 0..4, best per row
cost = np.stack([np.abs(((f + 128) & 0xFF) - 128).sum(1) for f in cands])
best = cost.argmin(0)
raw = b"".join(bytes([k]) + (cands[k][y] & 0xFF).astype(np.uint8).tobytes() for y, k in enumerate(best))
def chunk(t, d): return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
open(out, "wb").write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))
