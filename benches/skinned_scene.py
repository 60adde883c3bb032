#!/usr/bin/env python3
"""A skinned benchmark scene with many joints, as glTF 2.0 binary (.glb), for benches/frame.sh.

    python3 benches/skinned_scene.py --tubes 16 --joints 8 --triangles 16384 --out skinned.glb

A floor (two triangles) and TUBES swaying tubes on a grid, each a chain of JOINTS joints
(TUBES x JOINTS joints in one skin); every tube vertex is weighted between the two joints
nearest along the chain. The animation turns every joint about x and z, one LINEAR
rotation channel per joint with KEYS keys over the clip; the tubes bend into one another
at mid-clip. One perspective camera, one KHR_lights_punctual point light;
scenes[0].extras.fps gives the frame rate (as ../shared/peers/gen_scene.py does).
Deterministic: same arguments, same bytes. Only numpy + stdlib.
"""
import argparse, json, math, struct

import numpy as np


def quat_axis_angle(axis, angle):
    axis = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    s = math.sin(angle / 2)
    return [axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2)]


def quat_mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return [aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tubes", type=int, default=16)
    ap.add_argument("--joints", type=int, default=8, help="joints per tube")
    ap.add_argument("--triangles", type=int, default=16384, help="tube triangles (about)")
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--keys", type=int, default=31)
    ap.add_argument("--out", default="skinned.glb")
    a = ap.parse_args()
    ring = 8
    segs = max(a.joints, a.triangles // (a.tubes * 2 * ring))   # segments along a tube
    height, radius = 4.0, 0.12
    side = math.ceil(math.sqrt(a.tubes))
    bases = [((k % side - (side - 1) / 2) * 0.6, 0.0, (k // side - (side - 1) / 2) * 0.6)
             for k in range(a.tubes)]
    pos, joints, weights, idx = [], [], [], []
    seg_len = height / a.joints
    for t, (bx, by, bz) in enumerate(bases):
        first = len(pos)
        for s in range(segs + 1):
            y = height * s / segs
            c = y / seg_len - 0.5                                 # position along the chain
            j0 = int(min(max(math.floor(c), 0), a.joints - 1))
            j1 = min(j0 + 1, a.joints - 1)
            w1 = min(max(c - j0, 0.0), 1.0) if j1 != j0 else 0.0
            for r in range(ring):
                ang = 2 * math.pi * r / ring
                pos.append((bx + radius * math.cos(ang), by + y, bz + radius * math.sin(ang)))
                joints.append((t * a.joints + j0, t * a.joints + j1, 0, 0))
                weights.append((1.0 - w1, w1, 0.0, 0.0))
        for s in range(segs):
            for r in range(ring):
                p00 = first + s * ring + r
                p01 = first + s * ring + (r + 1) % ring
                p10, p11 = p00 + ring, p01 + ring
                idx += [p00, p10, p01, p01, p10, p11]
    floor_first = len(pos)
    for x, z in ((-6, -6), (6, -6), (6, 6), (-6, 6)):
        pos.append((x, -0.01, z))
    floor_idx = [floor_first, floor_first + 2, floor_first + 1, floor_first, floor_first + 3, floor_first + 2]
    pos = np.array(pos, np.float32)
    n_joint_nodes = a.tubes * a.joints
    # Node 0: the tube mesh (skinned); 1: the floor; 2: camera; 3: light; then the joints.
    J0 = 4
    nodes = [{"name": "tubes", "mesh": 0, "skin": 0}, {"name": "floor", "mesh": 1}]
    eye, target = np.array([0.0, 3.0, 7.5]), np.array([0.0, 2.0, 0.0])
    f = target - eye; f /= np.linalg.norm(f)
    pitch = math.asin(f[1])
    nodes.append({"name": "camera", "camera": 0, "translation": eye.tolist(),
                  "rotation": quat_axis_angle([1, 0, 0], pitch)})
    nodes.append({"name": "light", "translation": [2.0, 7.0, 4.0],
                  "extensions": {"KHR_lights_punctual": {"light": 0}}})
    ibms = []
    for t, (bx, by, bz) in enumerate(bases):
        for j in range(a.joints):
            n = {"name": f"tube{t}_joint{j}",
                 "translation": [bx, by, bz] if j == 0 else [0.0, seg_len, 0.0]}
            if j + 1 < a.joints:
                n["children"] = [J0 + t * a.joints + j + 1]
            nodes.append(n)
            m = np.eye(4, dtype=np.float32)
            m[:3, 3] = [-bx, -(by + j * seg_len), -bz]
            ibms.append(m.T.reshape(-1))                         # column-major
    blob = bytearray()
    views, accessors = [], []

    def add(arr, ctype, typ, target=None, minmax=False):
        data = np.ascontiguousarray(arr).tobytes()
        while len(blob) % 4:
            blob.append(0)
        view = {"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)}
        if target:
            view["target"] = target
        views.append(view)
        blob.extend(data)
        acc = {"bufferView": len(views) - 1, "componentType": ctype, "count": len(arr), "type": typ}
        if minmax:
            a2 = np.asarray(arr).reshape(len(arr), -1)
            acc["min"] = a2.min(0).tolist()
            acc["max"] = a2.max(0).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    tube_pos = add(pos[:floor_first], 5126, "VEC3", 34962, True)
    tube_j = add(np.array(joints, np.uint16), 5123, "VEC4", 34962)
    tube_w = add(np.array(weights, np.float32), 5126, "VEC4", 34962)
    tube_i = add(np.array(idx, np.uint32), 5125, "SCALAR", 34963)
    floor_pos = add(pos[floor_first:], 5126, "VEC3", 34962, True)
    floor_i = add(np.array([i - floor_first for i in floor_idx], np.uint32), 5125, "SCALAR", 34963)
    ibm = add(np.array(ibms, np.float32), 5126, "MAT4")
    duration = a.frames / a.fps
    times = np.array([duration * k / (a.keys - 1) for k in range(a.keys)], np.float32)
    t_acc = add(times, 5126, "SCALAR", None, True)
    channels, samplers = [], []
    for t in range(a.tubes):
        for j in range(a.joints):
            q = []
            for k in range(a.keys):
                ph = 2 * math.pi * k / (a.keys - 1)
                bend = 0.25 * (0.5 - 0.5 * math.cos(2 * ph))        # most bent at mid-clip
                ax = bend * math.sin(ph + 0.7 * t + 0.4 * j)
                az = bend * math.cos(1.3 * ph + 0.5 * t - 0.3 * j)
                q.append(quat_mul(quat_axis_angle([1, 0, 0], ax), quat_axis_angle([0, 0, 1], az)))
            samplers.append({"input": t_acc, "output": add(np.array(q, np.float32), 5126, "VEC4"),
                             "interpolation": "LINEAR"})
            channels.append({"sampler": len(samplers) - 1,
                             "target": {"node": J0 + t * a.joints + j, "path": "rotation"}})
    roots = [J0 + t * a.joints for t in range(a.tubes)]
    gltf = {
        "asset": {"version": "2.0", "generator": "subfield benches/skinned_scene.py"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [
            # candela (KHR_lights_punctual): 400 W/sr in subfield's radiometric unit
            {"type": "point", "color": [1, 1, 1], "intensity": 400.0 * 683}]}},
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2, 3] + roots, "extras": {"fps": a.fps}}],
        "nodes": nodes,
        "meshes": [
            {"name": "tubes", "primitives": [{"attributes": {"POSITION": tube_pos, "JOINTS_0": tube_j,
                                                             "WEIGHTS_0": tube_w},
                                              "indices": tube_i, "material": 0}]},
            {"name": "floor", "primitives": [{"attributes": {"POSITION": floor_pos},
                                              "indices": floor_i, "material": 1}]},
        ],
        "materials": [
            {"name": "tube", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.3, 0.2, 1],
                                                      "metallicFactor": 0.0, "roughnessFactor": 0.5}},
            {"name": "floor", "pbrMetallicRoughness": {"baseColorFactor": [0.7, 0.7, 0.7, 1],
                                                       "metallicFactor": 1.0, "roughnessFactor": 0.0}},
        ],
        "skins": [{"joints": list(range(J0, J0 + n_joint_nodes)), "inverseBindMatrices": ibm}],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.9, "znear": 0.05, "aspectRatio": 4 / 3}}],
        "animations": [{"name": "sway", "channels": channels, "samplers": samplers}],
        "buffers": [{"byteLength": 0}],
        "bufferViews": views,
        "accessors": accessors,
    }
    while len(blob) % 4:
        blob.append(0)
    gltf["buffers"][0]["byteLength"] = len(blob)
    js = json.dumps(gltf, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    out = struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(js) + 8 + len(blob))
    out += struct.pack("<II", len(js), 0x4E4F534A) + js
    out += struct.pack("<II", len(blob), 0x004E4942) + bytes(blob)
    open(a.out, "wb").write(out)
    print(json.dumps({"out": a.out, "bytes": len(out), "tube_tris": len(idx) // 3, "floor_tris": 2,
                      "joints": n_joint_nodes, "frames": a.frames, "keys": a.keys}))


if __name__ == "__main__":
    main()
