#!/usr/bin/env python3
"""Writes the USD test scenes of tests/usd_scenes.rs with Pixar's own library (usd-core,
`pip install usd-core`), the way simulation tools write caches, and beside each scene
the reference the Rust test checks a render against: for every frame asked, the world
triangles and the camera, evaluated by usd-core itself (`GetPointsAttr().Get(t)`,
`ComputeLocalToWorldTransform(t)`), in the stage's own units and up axis.

usage: make_scenes.py OUT_DIR

Scenes:
  shatter.usda   Z up, centimetres: a ground (static), a shattering sheet whose every
                 face flies on its own path (time-sampled points), a spinning cube
                 (time-sampled translate / rotateXYZ / scale on its parent Xform, an orient
                 on the cube), a moving camera (time-sampled xformOp:transform).
  fluid.usda     Y up, metres: a surface whose face count changes every frame, with
                 velocities; a still camera.
  clips/shot.usda  the shatter animation as one file a frame (clips/frame.N.usda),
                 stitched into value clips by UsdUtils.StitchClips (usdstitchclips).
  shatter.usdz   shatter.usda packaged (UsdUtils.CreateNewUsdzPackage).
  looks.usda     UsdPreviewSurface materials (one with a diffuseColor texture), a sphere
                 light and a distant light.
  area.usda      Y up, metres: a rect light at y = 2 and a disk light at x = 5, y = 2, both
                 turned to shine down (-Y), over a grey floor at y = 0.
  bad/...        broken inputs (see bad_inputs()), among them binary files with a
                 corrupt array length (overflow.usdc, huge.usdc, big.usdc,
                 short.usdc, wide.usdc).
"""
import json
import math
import os
import random
import struct
import sys

from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdUtils

FRAMES = list(range(1, 9))
GRID = 6  # GRID x GRID faces in the shattering sheet
CELL = 40.0  # cm


def shard_points(f):
    """Points of the shattering sheet at time code f: face k keeps its 4 corners, moves
    along its own direction and turns about its own axis (every face its own path)."""
    rng = random.Random(7)
    pts = []
    s = f - FRAMES[0]
    for j in range(GRID):
        for i in range(GRID):
            c = Gf.Vec3d((i - GRID / 2 + 0.5) * CELL, (j - GRID / 2 + 0.5) * CELL, 150.0)
            d = Gf.Vec3d(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.2, 1.0))
            axis = Gf.Vec3d(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)).GetNormalized()
            w = rng.uniform(-25, 25)
            rot = Gf.Rotation(axis, w * s)
            centre = c + d * (14.0 * s)
            h = CELL * 0.45
            for corner in [(-h, -h), (h, -h), (h, h), (-h, h)]:
                off = rot.TransformDir(Gf.Vec3d(corner[0], corner[1], 0.0))
                pts.append(Gf.Vec3f(centre + off))
    return pts


def camera_matrix(f, eye0, centre, up):
    eye = eye0 + Gf.Vec3d(8.0 * (f - FRAMES[0]), 0.0, 0.0)
    return Gf.Matrix4d().SetLookAt(eye, centre, up).GetInverse()


def author_shatter(stage, frames):
    """The shatter scene's prims, with samples at `frames` (all of them for the one
    file, one for each file of the clip sequence)."""
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    ground = UsdGeom.Mesh.Define(stage, "/World/Ground")
    g = 600.0
    ground.CreatePointsAttr([(-g, -g, 0), (g, -g, 0), (g, g, 0), (-g, g, 0)])
    ground.CreateFaceVertexCountsAttr([4])
    ground.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    ground.CreateDisplayColorAttr([(0.6, 0.6, 0.6)])

    sheet = UsdGeom.Mesh.Define(stage, "/World/Debris")
    n = GRID * GRID
    sheet.CreateFaceVertexCountsAttr([4] * n)
    sheet.CreateFaceVertexIndicesAttr(list(range(4 * n)))
    pts = sheet.CreatePointsAttr()
    for f in frames:
        pts.Set(shard_points(f), Usd.TimeCode(f))

    spin = UsdGeom.Xform.Define(stage, "/World/Spinner")
    t = spin.AddTranslateOp()
    r = spin.AddRotateXYZOp()
    sc = spin.AddScaleOp()
    for f in frames:
        s = f - FRAMES[0]
        t.Set(Gf.Vec3d(-220 + 20 * s, 200, 60 + 10 * s), Usd.TimeCode(f))
        r.Set(Gf.Vec3f(10 * s, 20 * s, 35 * s), Usd.TimeCode(f))
        sc.Set(Gf.Vec3f(1.0 + 0.05 * s, 1.0, 1.0 - 0.03 * s), Usd.TimeCode(f))
    cube = UsdGeom.Mesh.Define(stage, "/World/Spinner/Cube")
    cube.AddOrientOp().Set(Gf.Quatf(Gf.Rotation(Gf.Vec3d(1, 1, 0), 30).GetQuat()))
    e = 40.0
    cube.CreatePointsAttr([(x, y, z) for z in (-e, e) for y in (-e, e) for x in (-e, e)])
    cube.CreateFaceVertexCountsAttr([4] * 6)
    cube.CreateFaceVertexIndicesAttr(
        [0, 2, 3, 1, 4, 5, 7, 6, 0, 1, 5, 4, 2, 6, 7, 3, 0, 4, 6, 2, 1, 3, 7, 5]
    )

    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    cam.CreateFocalLengthAttr(30.0)
    cam.CreateHorizontalApertureAttr(36.0)
    cam.CreateVerticalApertureAttr(24.0)
    cam.CreateClippingRangeAttr(Gf.Vec2f(1.0, 100000.0))
    op = cam.AddTransformOp()
    for f in frames:
        op.Set(camera_matrix(f, Gf.Vec3d(0, -1100, 520), Gf.Vec3d(0, 0, 120), Gf.Vec3d(0, 0, 1)), Usd.TimeCode(f))


def fluid_faces(f):
    """A strip whose column count grows with the frame: 2 + f quads, so every frame has
    another face count; its points rise over time (velocities give the rate)."""
    cols = 2 + f
    pts, vel, counts, idx = [], [], [], []
    for c in range(cols + 1):
        x = -2.0 + 4.0 * c / cols
        for y in (-1.0, 1.0):
            z = -0.3 * math.sin(1.3 * x + 0.4 * f)
            pts.append(Gf.Vec3f(x, y + 0.05 * f, z))
            vel.append(Gf.Vec3f(0.0, 0.05 * 24.0, 0.0))
    for c in range(cols):
        counts.append(4)
        idx += [2 * c, 2 * c + 2, 2 * c + 3, 2 * c + 1]
    return pts, vel, counts, idx


def author_fluid(stage):
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    m = UsdGeom.Mesh.Define(stage, "/World/Surface")
    for f in FRAMES:
        pts, vel, counts, idx = fluid_faces(f)
        tc = Usd.TimeCode(f)
        m.GetPointsAttr().Set(pts, tc)
        m.CreateVelocitiesAttr().Set(vel, tc)
        m.GetFaceVertexCountsAttr().Set(counts, tc)
        m.GetFaceVertexIndicesAttr().Set(idx, tc)
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    cam.CreateFocalLengthAttr(24.0)
    cam.CreateHorizontalApertureAttr(36.0)
    cam.CreateVerticalApertureAttr(24.0)
    cam.AddTranslateOp().Set(Gf.Vec3d(0.2, 0.3, 6.0))


def write_png(path, w, h, pixel):
    """An RGB PNG, written by hand (zlib), so the script needs no imaging library."""
    import struct
    import zlib

    raw = b"".join(b"\x00" + b"".join(bytes(pixel(x, y)) for x in range(w)) for y in range(h))

    def chunk(tag, data):
        c = struct.pack(">I", len(data)) + tag + data
        return c + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")
    with open(path, "wb") as f:
        f.write(png)


def author_looks(path):
    """UsdPreviewSurface materials (constant inputs; a diffuseColor texture), lights."""
    from pxr import UsdLux, UsdShade

    stage = Usd.Stage.CreateNew(path)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    write_png(os.path.join(os.path.dirname(path), "checker.png"), 4, 4,
              lambda x, y: (255, 0, 0) if (x + y) % 2 else (0, 0, 255))
    for k, name in enumerate(("Plain", "Textured")):
        m = UsdGeom.Mesh.Define(stage, "/World/%s" % name)
        x = 2.0 * k
        m.CreatePointsAttr([(x, 0, 0), (x + 1, 0, 0), (x + 1, 1, 0), (x, 1, 0)])
        m.CreateFaceVertexCountsAttr([4])
        m.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
        st = UsdGeom.PrimvarsAPI(m).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                  UsdGeom.Tokens.faceVarying)
        st.Set([(0, 0), (1, 0), (1, 1), (0, 1)])
        mat = UsdShade.Material.Define(stage, "/World/Looks/%s" % name)
        sh = UsdShade.Shader.Define(stage, "/World/Looks/%s/Surface" % name)
        sh.CreateIdAttr("UsdPreviewSurface")
        sh.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.25)
        sh.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.75)
        sh.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f).Set((0.5, 0.25, 0.0))
        sh.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(1.0)
        if name == "Plain":
            sh.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set((0.8, 0.2, 0.1))
        else:
            tex = UsdShade.Shader.Define(stage, "/World/Looks/%s/Tex" % name)
            tex.CreateIdAttr("UsdUVTexture")
            tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("./checker.png")
            out = tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
            sh.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(out)
        mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
        UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(mat)
    sphere = UsdLux.SphereLight.Define(stage, "/World/Bulb")
    sphere.CreateIntensityAttr(1000.0)
    sphere.CreateExposureAttr(1.0)
    sphere.CreateRadiusAttr(0.1)
    sphere.CreateColorAttr((1.0, 0.5, 0.25))
    UsdGeom.Xformable(sphere).AddTranslateOp().Set(Gf.Vec3d(0, 3, 2))
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr(50000.0)
    sun.CreateAngleAttr(0.53)
    stage.GetRootLayer().Save()


def author_area(path):
    stage = Usd.Stage.CreateNew(path)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.Xform.Define(stage, "/World")
    floor = UsdGeom.Mesh.Define(stage, "/World/Floor")
    floor.CreatePointsAttr([(-10, 0, -10), (10, 0, -10), (10, 0, 10), (-10, 0, 10)])
    floor.CreateFaceVertexCountsAttr([4])
    floor.CreateFaceVertexIndicesAttr([0, 3, 2, 1])
    floor.CreateDisplayColorAttr([(0.5, 0.5, 0.5)])
    rect = UsdLux.RectLight.Define(stage, "/World/Panel")
    rect.CreateWidthAttr(2.0)
    rect.CreateHeightAttr(1.0)
    rect.CreateIntensityAttr(683.0)
    rect.CreateExposureAttr(1.0)
    rect.CreateColorAttr((1.0, 0.5, 0.25))
    x = UsdGeom.Xformable(rect)
    x.AddTranslateOp().Set(Gf.Vec3d(0, 2, 0))
    # Local -Z (the way a rect light shines) turned to world -Y.
    x.AddRotateXOp().Set(-90.0)
    disk = UsdLux.DiskLight.Define(stage, "/World/Spot")
    disk.CreateRadiusAttr(0.5)
    disk.CreateIntensityAttr(100.0)
    disk.CreateNormalizeAttr(True)
    x = UsdGeom.Xformable(disk)
    x.AddTranslateOp().Set(Gf.Vec3d(5, 2, 0))
    x.AddRotateXOp().Set(-90.0)
    stage.GetRootLayer().Save()


def new_stage(path, start, end):
    stage = Usd.Stage.CreateNew(path)
    stage.SetStartTimeCode(start)
    stage.SetEndTimeCode(end)
    stage.SetTimeCodesPerSecond(24)
    return stage


def reference(path, frames):
    """World triangles (fans of each face, stage units and axes) and the camera, per
    frame, as usd-core evaluates them."""
    stage = Usd.Stage.Open(path)
    out = {
        "metersPerUnit": UsdGeom.GetStageMetersPerUnit(stage),
        "upAxis": UsdGeom.GetStageUpAxis(stage),
        "frames": {},
    }
    for f in frames:
        tc = Usd.TimeCode(f)
        cache = UsdGeom.XformCache(tc)
        tris = []
        cam = None
        for prim in stage.Traverse():
            if prim.IsA(UsdGeom.Mesh):
                mesh = UsdGeom.Mesh(prim)
                m = cache.GetLocalToWorldTransform(prim)
                pts = [m.Transform(Gf.Vec3d(p)) for p in mesh.GetPointsAttr().Get(tc)]
                counts = mesh.GetFaceVertexCountsAttr().Get(tc)
                idx = mesh.GetFaceVertexIndicesAttr().Get(tc)
                k = 0
                for c in counts:
                    for j in range(1, c - 1):
                        for v in (idx[k], idx[k + j], idx[k + j + 1]):
                            tris.extend(pts[v])
                    k += c
            elif prim.IsA(UsdGeom.Camera):
                c = UsdGeom.Camera(prim)
                m = c.ComputeLocalToWorldTransform(tc)
                cam = {
                    # Row-vector matrix, row-major: rows 0..2 the axes, row 3 the origin.
                    "matrix": [m[r][k] for r in range(4) for k in range(4)],
                    "focalLength": c.GetFocalLengthAttr().Get(tc),
                    "horizontalAperture": c.GetHorizontalApertureAttr().Get(tc),
                    "verticalAperture": c.GetVerticalApertureAttr().Get(tc),
                }
        out["frames"][str(f)] = {"triangles": tris, "camera": cam}
    return out


def write_json(path, value):
    with open(path, "w") as f:
        json.dump(value, f)


def bad_inputs(bad):
    """Broken inputs: each must fail with one line naming file, prim and attribute."""
    os.makedirs(bad, exist_ok=True)
    # A mesh with an index past its points.
    s = Usd.Stage.CreateNew(os.path.join(bad, "indices.usda"))
    m = UsdGeom.Mesh.Define(s, "/World/Broken")
    m.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    m.CreateFaceVertexCountsAttr([3])
    m.CreateFaceVertexIndicesAttr([0, 1, 7])
    s.GetRootLayer().Save()
    # A syntax error.
    with open(os.path.join(bad, "syntax.usda"), "w") as f:
        f.write('#usda 1.0\n\ndef Mesh "M" {\n    point3f[] points = [(0, 0, 0), (1, 0\n}\n')
    # A truncated usdc: a good binary file cut in half.
    s = Usd.Stage.CreateNew(os.path.join(bad, "whole.usdc"))
    m = UsdGeom.Mesh.Define(s, "/World/M")
    m.CreatePointsAttr([(i, 0, 0) for i in range(300)])
    s.GetRootLayer().Save()
    data = open(os.path.join(bad, "whole.usdc"), "rb").read()
    with open(os.path.join(bad, "truncated.usdc"), "wb") as f:
        f.write(data[: len(data) // 2])
    os.remove(os.path.join(bad, "whole.usdc"))
    # Corrupt array lengths in a good binary file, as a bad disk or a crashed writer
    # leaves them: the length of the points array (1,237 Vec3f, stored uncompressed
    # after its 8-byte length) set past what a length can address (the USD reader's
    # allocation overflows), to 2^58 (an allocation no machine can make), to 2^29 (6 GiB:
    # one many machines can make, far more than the file can hold) and to 80,000,000
    # (0.9 GiB: within what a file may decode to, for a test under a memory limit).
    def points_file(n):
        """A .usdc of one mesh with n points, its bytes, and where the points' length is."""
        path = os.path.join(bad, "points_src.usdc")
        s = Usd.Stage.CreateNew(path)
        m = UsdGeom.Mesh.Define(s, "/World/Sheet")
        pts = [(i * 0.5 + 0.25, 1.0, 2.0) for i in range(n)]
        m.CreatePointsAttr(pts)
        m.CreateFaceVertexCountsAttr([3])
        m.CreateFaceVertexIndicesAttr([0, 1, 2])
        s.GetRootLayer().Save()
        data = open(path, "rb").read()
        os.remove(path)
        first = struct.pack("<Q", n) + struct.pack("<3f", *pts[0])
        at = data.find(first)
        assert at >= 0 and data.find(first, at + 1) < 0, "points array not found once"
        return data, at

    data, at = points_file(1237)
    for name, count in (
        ("overflow.usdc", (1 << 63) | 1237),
        ("huge.usdc", 1 << 58),
        ("big.usdc", 1 << 29),
        ("short.usdc", 80_000_000),
    ):
        with open(os.path.join(bad, name), "wb") as f:
            f.write(data[:at] + struct.pack("<Q", count) + data[at + 8:])
    # A file large enough that its bound is 8,192 times its size (not 1 GiB), with a
    # length of 1.5 times that bound: refused only when the reader's layers are counted
    # once each (it opens the root layer twice).
    data, at = points_file(20000)
    assert len(data) * 8192 > 1 << 30, "wide.usdc too small for its bound to pass 1 GiB"
    count = len(data) * 8192 * 3 // 2 // 12
    with open(os.path.join(bad, "wide.usdc"), "wb") as f:
        f.write(data[:at] + struct.pack("<Q", count) + data[at + 8:])
    # A cycle of sublayers.
    for a, b in (("cycle_a.usda", "cycle_b.usda"), ("cycle_b.usda", "cycle_a.usda")):
        with open(os.path.join(bad, a), "w") as f:
            f.write('#usda 1.0\n(\n    subLayers = [@./%s@]\n)\n\ndef Xform "World" {}\n' % b)
    # A reference out of the scene's folder (to a file that exists there).
    os.makedirs(os.path.join(bad, "inner"), exist_ok=True)
    with open(os.path.join(bad, "outside_target.usda"), "w") as f:
        f.write('#usda 1.0\n\ndef Xform "Asset" {}\n')
    with open(os.path.join(bad, "inner", "outside.usda"), "w") as f:
        f.write('#usda 1.0\n\ndef Xform "World" (\n    references = @../outside_target.usda@</Asset>\n) {}\n')
    # A missing sublayer.
    with open(os.path.join(bad, "missing.usda"), "w") as f:
        f.write('#usda 1.0\n(\n    subLayers = [@./nowhere.usda@]\n)\n\ndef Xform "World" {}\n')


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    shatter = os.path.join(out, "shatter.usda")
    stage = new_stage(shatter, FRAMES[0], FRAMES[-1])
    author_shatter(stage, FRAMES)
    stage.GetRootLayer().Save()
    write_json(os.path.join(out, "shatter.json"), reference(shatter, [1, 4, 8]))

    fluid = os.path.join(out, "fluid.usda")
    stage = new_stage(fluid, FRAMES[0], FRAMES[-1])
    author_fluid(stage)
    stage.GetRootLayer().Save()
    write_json(os.path.join(out, "fluid.json"), reference(fluid, [1, 2, 5, 8]))

    # Houdini-style: one file a frame, stitched into value clips.
    clips = os.path.join(out, "clips")
    os.makedirs(clips, exist_ok=True)
    files = []
    for f in FRAMES:
        p = os.path.join(clips, "frame.%d.usda" % f)
        s = new_stage(p, f, f)
        author_shatter(s, [f])
        s.GetRootLayer().Save()
        files.append(p)
    shot = os.path.join(clips, "shot.usda")
    layer = Sdf.Layer.CreateNew(shot)
    UsdUtils.StitchClips(layer, files, Sdf.Path("/World"), FRAMES[0], FRAMES[-1])
    # Stage metadata is the root layer's alone: the stitched root states the units, up
    # axis and rate again (the topology sublayer's are not the stage's).
    layer.Save()
    s = Usd.Stage.Open(shot)
    UsdGeom.SetStageUpAxis(s, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(s, 0.01)
    s.SetTimeCodesPerSecond(24)
    s.GetRootLayer().Save()

    # The shatter scene as a usdz package.
    UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(shatter), os.path.join(out, "shatter.usdz"))

    author_looks(os.path.join(out, "looks.usda"))
    author_area(os.path.join(out, "area.usda"))

    bad_inputs(os.path.join(out, "bad"))


if __name__ == "__main__":
    main()
