#!/usr/bin/env python3
"""The peer of benches/usd_cache.rs: Pixar's usd-core does the work subfield's import and
per-frame posing do on the same file. Prints the seconds `Usd.Stage.Open` took and the
median milliseconds a frame of: every mesh's `points` at that time code, moved by its
local-to-world transform (what `Scene::dynamic_triangles_at` gives, before the fans),
the points read as one array (`numpy.asarray` on the Vt array, no copy per point) and
moved by one matrix product, so Python's per-point cost is not counted against usd-core.

usage: usd_core_peer.py FILE.usda FRAMES   (frames 1..=FRAMES)
"""
import statistics
import sys
import time

import numpy as np

from pxr import Usd, UsdGeom


def main():
    path, frames = sys.argv[1], int(sys.argv[2])
    t0 = time.perf_counter()
    stage = Usd.Stage.Open(path)
    meshes = [UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    open_s = time.perf_counter() - t0
    per = []
    for f in range(1, frames + 1):
        t0 = time.perf_counter()
        tc = Usd.TimeCode(f)
        cache = UsdGeom.XformCache(tc)
        n = 0
        for m in meshes:
            xf = np.array(cache.GetLocalToWorldTransform(m.GetPrim()), dtype=np.float32)
            pts = np.asarray(m.GetPointsAttr().Get(tc), dtype=np.float32)
            # Row vectors, as USD's matrices take them: p' = p · M[:3, :3] + M[3, :3].
            world = pts @ xf[:3, :3] + xf[3, :3]
            n += len(world)
        per.append((time.perf_counter() - t0) * 1e3)
        assert n > 0
    print(f"{open_s:.4f} {statistics.median(per):.4f}")


if __name__ == "__main__":
    main()
