#!/usr/bin/env python3
"""A variant of a generated benchmark scene (../shared/peers/gen_scene.py) for shading
benchmarks: more point lights, a base colour texture on its first mesh, or a sun.

    python3 benches/scene_variant.py IN.glb OUT.glb --lights 6
    python3 benches/scene_variant.py IN.glb OUT.glb --texture 256
    python3 benches/scene_variant.py IN.glb OUT.glb --sun z

--lights N: N point lights in all, the file's first light copied to N-1 more nodes at
fixed places in the generator's room (N at most 6). --texture S: an S x S RGB PNG
(checkers over noise, fixed seed) as the base colour texture of the first mesh's
material, with TEXCOORD_0 made from its positions (a planar mapping). --sun z|tilt: the
file's light made a directional one (intensity 3) on its node, unrotated (z: it shines
along -Z, so its shadow rays run along +Z exactly, two direction components zero) or
turned 40 degrees about (0.6, 0.8, 0) (tilt); not with --lights. Any may be combined.
Deterministic: same input and arguments, same bytes. Only numpy + stdlib.
"""
import argparse
import json
import struct
import zlib

import numpy as np

PLACES = [[-6, 6, -6], [6, 6, -6], [-6, 6, 6], [6, 6, 6], [0, 7, 0]]


def read_glb(path):
    b = open(path, "rb").read()
    if b[:4] != b"glTF":
        raise SystemExit(f"{path}: not a .glb")
    ln, = struct.unpack_from("<I", b, 12)
    js = json.loads(b[20:20 + ln])
    off = 20 + ln
    bl, = struct.unpack_from("<I", b, off)
    return js, bytearray(b[off + 8:off + 8 + bl])


def write_glb(path, js, binary):
    while len(binary) % 4:
        binary.append(0)
    js["buffers"][0]["byteLength"] = len(binary)
    j = json.dumps(js).encode()
    j += b" " * (-len(j) % 4)
    body = struct.pack("<II", len(j), 0x4E4F534A) + j + struct.pack("<II", len(binary), 0x004E4942) + bytes(binary)
    with open(path, "wb") as f:
        f.write(struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body)


def add_view(js, binary, data, target=None):
    while len(binary) % 4:
        binary.append(0)
    view = {"buffer": 0, "byteOffset": len(binary), "byteLength": len(data)}
    if target:
        view["target"] = target
    binary += data
    js["bufferViews"].append(view)
    return len(js["bufferViews"]) - 1


def png(img):
    h, w, _ = img.shape
    raw = b"".join(b"\x00" + img[y].tobytes() for y in range(h))

    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("input")
    ap.add_argument("output")
    ap.add_argument("--lights", type=int, default=0)
    ap.add_argument("--texture", type=int, default=0)
    ap.add_argument("--sun", choices=["z", "tilt"])
    a = ap.parse_args()
    if a.sun and a.lights:
        raise SystemExit("--sun and --lights do not go together")
    js, binary = read_glb(a.input)
    if a.sun:
        lights = js.get("extensions", {}).get("KHR_lights_punctual", {}).get("lights", [])
        node = next((n for n in js["nodes"] if "KHR_lights_punctual" in n.get("extensions", {})), None)
        if not lights or node is None:
            raise SystemExit(f"{a.input}: no light to turn into a sun")
        lights[node["extensions"]["KHR_lights_punctual"]["light"]] = {
            "type": "directional", "color": [1, 1, 1], "intensity": 3.0, "name": "sun"}
        node.pop("translation", None)
        node.pop("rotation", None)
        if a.sun == "tilt":
            h = np.radians(-40.0) / 2
            node["rotation"] = [0.6 * np.sin(h), 0.8 * np.sin(h), 0.0, np.cos(h)]
    if a.lights:
        lights = js.get("extensions", {}).get("KHR_lights_punctual", {}).get("lights", [])
        node = next((n for n in js["nodes"] if "KHR_lights_punctual" in n.get("extensions", {})), None)
        if not lights or node is None:
            raise SystemExit(f"{a.input}: no light to copy")
        if not 1 <= a.lights <= len(PLACES) + 1:
            raise SystemExit(f"--lights takes 1 to {len(PLACES) + 1}")
        light = node["extensions"]["KHR_lights_punctual"]["light"]
        for i, p in enumerate(PLACES[:a.lights - 1]):
            js["nodes"].append({"name": f"light{i + 2}", "translation": p,
                                "extensions": {"KHR_lights_punctual": {"light": light}}})
            js["scenes"][0]["nodes"].append(len(js["nodes"]) - 1)
    if a.texture:
        prim = js["meshes"][0]["primitives"][0]
        acc = js["accessors"][prim["attributes"]["POSITION"]]
        view = js["bufferViews"][acc["bufferView"]]
        pos = np.frombuffer(bytes(binary), np.float32, count=acc["count"] * 3,
                            offset=view.get("byteOffset", 0) + acc.get("byteOffset", 0)).reshape(-1, 3)
        uv = np.stack([pos[:, 0] * 0.37 + pos[:, 1] * 0.21, pos[:, 2] * 0.37 - pos[:, 1] * 0.17], 1)
        uv = np.ascontiguousarray(uv, np.float32)
        js["accessors"].append({"bufferView": add_view(js, binary, uv.tobytes(), 34962),
                                "componentType": 5126, "count": len(uv), "type": "VEC2"})
        prim["attributes"]["TEXCOORD_0"] = len(js["accessors"]) - 1
        s = a.texture
        rng = np.random.default_rng(3)
        img = rng.integers(60, 255, (s, s, 3)).astype(np.uint8)
        img[(np.indices((s, s)).sum(0) // 32) % 2 == 0] //= 2
        js["images"] = [{"bufferView": add_view(js, binary, png(img)), "mimeType": "image/png"}]
        js["samplers"] = [{}]
        js["textures"] = [{"source": 0, "sampler": 0}]
        if prim.get("material") is None:
            js.setdefault("materials", []).append({"pbrMetallicRoughness": {}})
            prim["material"] = len(js["materials"]) - 1
        pbr = js["materials"][prim["material"]].setdefault("pbrMetallicRoughness", {})
        pbr["baseColorTexture"] = {"index": 0}
    write_glb(a.output, js, binary)


if __name__ == "__main__":
    main()
