# Noise of Monte Carlo renders per material mask (benches/blender_bounces.sh), with the
# system python3 (OpenEXR + numpy).
# run: python3 benches/noise.py REFERENCE.exr OTHER.exr [OTHER.exr ...]
# REFERENCE.exr has the albedo AOV: its distinct colours, eroded by one pixel, are the
# material masks (as in blender_units_compare.py), taken where every image's alpha is 1.
# For each OTHER and material: the RMS over the mask of (OTHER - REFERENCE) in R+G+B,
# divided by the reference's mean R+G+B there. With a reference of many more samples this
# is the relative noise of OTHER a pixel.
import sys, OpenEXR, Imath, numpy as np


def load(path, names):
    f = OpenEXR.InputFile(path)
    dw = f.header()["dataWindow"]
    w, h = dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1
    pt = Imath.PixelType(Imath.PixelType.FLOAT)
    return np.stack([np.frombuffer(f.channel(c, pt), np.float32).reshape(h, w) for c in names], -1)


ref = load(sys.argv[1], ["R", "G", "B", "A"])
key = np.round(load(sys.argv[1], ["albedo.R", "albedo.G", "albedo.B"]), 3)
same = np.ones(key.shape[:2], bool)
for dy in (-1, 0, 1):
    for dx in (-1, 0, 1):
        same &= (np.roll(np.roll(key, dy, 0), dx, 1) == key).all(-1)
same[0, :] = same[-1, :] = same[:, 0] = same[:, -1] = False
others = [(p, load(p, ["R", "G", "B", "A"])) for p in sys.argv[2:]]
for _, o in others:
    same &= o[..., 3] > 0.999
same &= ref[..., 3] > 0.999
colours = sorted({tuple(float(x) for x in c) for c in key[same].reshape(-1, 3) if c.max() > 0})
print(f"{'albedo':>22} {'pixels':>7} " + " ".join(f"{p.split('/')[-1]:>18}" for p, _ in others))
for c in colours:
    mask = same & (key == np.array(c)).all(-1)
    r = ref[..., :3][mask].sum(-1)
    cells = []
    for _, o in others:
        d = o[..., :3][mask].sum(-1) - r
        cells.append(f"{np.sqrt((d * d).mean()) / r.mean():>18.4f}")
    print(f"{','.join(f'{x:g}' for x in c):>22} {mask.sum():>7} " + " ".join(cells))
