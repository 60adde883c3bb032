# Per-material comparison of subfield's direct light with Cycles' (issue 35's acceptance
# figure; benches/blender_units.sh runs it), with the system python3 (OpenEXR + numpy).
# run: python3 benches/blender_units_compare.py [--bounces] OURS.exr CYCLES.exr [CYCLES2.exr ...]
# (--bounces: OURS was rendered with --diffuse-bounces, where the ambient term is off, so
# nothing is subtracted)
# OURS.exr has the albedo AOV: its distinct colours are the material masks, eroded by one
# pixel (so edges, where the two renderers' pixels cover different surfaces, are left
# out), and only where Cycles' alpha is 1. Our direct light is RGB less the ambient term
# (0.05 × albedo: every material here is a rough dielectric, whose diffuse colour is its
# albedo). Prints, per material and Cycles image, the mean of R+G+B on each side and
# their ratio.
import sys, OpenEXR, Imath, numpy as np


def load(path, names):
    f = OpenEXR.InputFile(path)
    dw = f.header()["dataWindow"]
    w, h = dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1
    pt = Imath.PixelType(Imath.PixelType.FLOAT)
    return np.stack([np.frombuffer(f.channel(c, pt), np.float32).reshape(h, w) for c in names], -1)


bounce = sys.argv[1] == "--bounces"
if bounce:
    del sys.argv[1]
ours = load(sys.argv[1], ["R", "G", "B"])
albedo = load(sys.argv[1], ["albedo.R", "albedo.G", "albedo.B"])
direct = ours if bounce else ours - 0.05 * albedo
key = np.round(albedo, 3)
colours = {tuple(float(x) for x in c) for c in key.reshape(-1, 3) if c.max() > 0}
h, w, _ = key.shape
same = np.ones((h, w), bool)
for dy in (-1, 0, 1):
    for dx in (-1, 0, 1):
        shifted = np.roll(np.roll(key, dy, 0), dx, 1)
        same &= (shifted == key).all(-1)
same[0, :] = same[-1, :] = same[:, 0] = same[:, -1] = False
print(f"{'albedo':>22} {'pixels':>7} {'ours':>9} " + " ".join(f"{p.split('/')[-1]:>30}" for p in sys.argv[2:]))
for c in sorted(colours):
    row = []
    for p in sys.argv[2:]:
        cyc = load(p, ["R", "G", "B", "A"])
        mask = same & (key == np.array(c)).all(-1) & (cyc[..., 3] > 0.999)
        o = direct[mask].sum(-1).mean()
        y = cyc[..., :3][mask].sum(-1).mean()
        row.append((mask.sum(), o, y))
    n, o, _ = row[0]
    cells = " ".join(f"{y:>12.4f} ours/it {o / y:9.5f} " for (_, _, y) in row)
    name = ",".join(f"{x:g}" for x in c)
    print(f"{name:>22} {n:>7} {o:>9.4f} {cells}")
