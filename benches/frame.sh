#!/usr/bin/env bash
# The whole frame a user waits for (issue 23): `subfield render` per frame and by phase
# (its --stats CSV: update = posing + insertion, trace, shade, EXR write on the writer
# thread), beside Embree's eval + update + trace of the same frames and rays
# (../shared/peers/embree_anchor.py) and Blender Cycles' render of the same file and frames
# (../shared/peers/blender_peer.py), in one run, mean and worst frame.
#
#   benches/frame.sh [--quick] [--frames A:B] [--size WxH] [--threads T] [--in-flight N]
#                    [--configs STATIC:DYNAMIC:SEED,...] [--skinned JOINTS:TRIS|none]
#                    [--camera still|dolly] [--own-materials]
#                    [--repeat N] [--no-blender] [--out DIR]
#
# Equal work (issue 38; ../shared/peers/README.md): every generated scene is made a half
# mirror everywhere (glb_material.py SCENE 0.5 0.0) and Embree runs with --whitted, so both
# sides trace a camera ray, a shadow ray and a mirror ray at every pixel and a shadow ray at
# each mirror hit. The headline ratio is the WHOLE subfield process (import, bake, every
# frame, EXRs on disk: wall time / frames) against Embree's frame. --own-materials keeps the
# generator's materials (diffuse room, mirror movers) and runs Embree without --whitted: the
# unequal comparison of earlier tables, kept only to reproduce them. --camera dolly keys the
# camera on an arc (gen_scene.py --camera-path dolly): no camera ray repeats a frame's.
#
# Defaults: scenes of ../shared/peers/gen_scene.py (31 morph keys, one-hot LINEAR weights;
# frames 0 and 150 are its dense clusters) 10284:16384:1, 10284:16384:2, 10284:4096:3,
# 10284:65536:4; a skinned scene of benches/skinned_scene.py, 128 joints and 16,384
# triangles (Embree's harness poses morph weights only: no Embree column there); frames
# 0:24 (the first cluster spreading out, the issue's 24 frames); 640x480; threads = nproc;
# frames in flight: the render's own choice (--in-flight N passes --frames-in-flight N);
# --repeat 2. --quick: frames 0:6 at 320x240, the first two configurations. Each side runs
# N times, alternating which goes first; the table shows each side's median over its runs
# (of each figure) and the ratios run by run. subfield renders with --max-depth 1 (one
# shadow ray per light and one mirror bounce, the harness's workload plus shading); Cycles
# runs at 1 spp, 1 glossy/transmission bounce, no diffuse bounce, no denoising, persistent
# data, EXR with Z (blender_peer.py's settings), so its image is noisy where ours is not.
# Figures move by 5-10% on a shared machine: compare within one run.
#
# Needs python3 with embreex and numpy, gcc, and `blender` (apt-get install blender) unless
# --no-blender. Scenes, CSVs and raw JSON lines go to DIR (default target/frame-bench).
# SUBFIELD=BINARY runs that binary instead of building this tree's (a before/after pair).
set -euo pipefail
cd "$(dirname "$0")/.."

die() { echo "benches/frame.sh: $*" >&2; exit 1; }

FRAMES=0:24
SIZE=640x480
THREADS=$(nproc)
IN_FLIGHT=""
CONFIGS=10284:16384:1,10284:16384:2,10284:4096:3,10284:65536:4
SKINNED=128:16384
REPEAT=2
BLENDER=1
CAMERA=still
EQUAL=1
OUT=target/frame-bench
while [ $# -gt 0 ]; do
    case "$1" in
        --quick) FRAMES=0:6; SIZE=320x240; CONFIGS=10284:16384:1,10284:4096:3 ;;
        --frames) FRAMES=${2:?--frames needs a value}; shift ;;
        --size) SIZE=${2:?--size needs a value}; shift ;;
        --threads) THREADS=${2:?--threads needs a value}; shift ;;
        --in-flight) IN_FLIGHT=${2:?--in-flight needs a value}; shift ;;
        --configs) CONFIGS=${2:?--configs needs a value}; shift ;;
        --skinned) SKINNED=${2:?--skinned needs a value}; shift ;;
        --repeat) REPEAT=${2:?--repeat needs a value}; shift ;;
        --no-blender) BLENDER=0 ;;
        --camera) CAMERA=${2:?--camera needs still or dolly}; shift ;;
        --own-materials) EQUAL=0 ;;
        --out) OUT=${2:?--out needs a value}; shift ;;
        -h|--help) sed -n '2,38p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) die "unknown option $1 (see --help)" ;;
    esac
    shift
done

PEERS=${PEERS:-../shared/peers}
[[ "$CAMERA" =~ ^(still|dolly)$ ]] || die "--camera takes still or dolly (got $CAMERA)"
[[ "$FRAMES" =~ ^([0-9]+):([0-9]+)$ ]] || die "--frames needs A:B, whole numbers (got $FRAMES)"
F0=${BASH_REMATCH[1]}; F1=${BASH_REMATCH[2]}
((F1 > F0)) || die "--frames A:B needs B > A (got $FRAMES)"
[[ "$SIZE" =~ ^([0-9]+)x([0-9]+)$ ]] || die "--size needs WxH (got $SIZE)"
W=${BASH_REMATCH[1]}; H=${BASH_REMATCH[2]}
[[ -z "$IN_FLIGHT" || "$IN_FLIGHT" =~ ^[1-9][0-9]*$ ]] || die "--in-flight needs a whole number, 1 or more (got $IN_FLIGHT)"
in_flight=()
[ -n "$IN_FLIGHT" ] && in_flight=(--frames-in-flight "$IN_FLIGHT")
[[ "$REPEAT" =~ ^[1-9][0-9]*$ ]] || die "--repeat needs a whole number of runs, 1 or more (got $REPEAT)"
command -v python3 >/dev/null || die "python3 is missing"
python3 -c "import numpy" 2>/dev/null || die "python3 cannot import numpy: pip install numpy"
EMBREE=1
if ! python3 -c "import embreex" 2>/dev/null || ! command -v gcc >/dev/null; then
    echo >&2 "benches/frame.sh: no embreex or gcc: the Embree columns are left out (pip install embreex)"
    EMBREE=0
fi
if ((BLENDER)) && ! command -v blender >/dev/null; then
    echo >&2 "benches/frame.sh: no blender: the Cycles column is left out (apt-get install blender)"
    BLENDER=0
fi
for f in gen_scene.py embree_anchor.py blender_peer.py glb_material.py; do
    [ -f "$PEERS/$f" ] || die "$PEERS/$f is not there (set PEERS)"
done
mkdir -p "$OUT"
if [ -z "${SUBFIELD:-}" ]; then
    echo >&2 "building ..."
    cargo build -q --release --bin subfield || die "cargo build failed"
    SUBFIELD=./target/release/subfield
fi
[ -x "$SUBFIELD" ] || die "$SUBFIELD is not an executable"

echo "# The whole frame: subfield render against Embree and Blender Cycles"
echo
echo "* machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
echo "* load before the run: $(uptime | sed 's/.*load average/load average/')"
echo "* frames $F0..$F1 (Embree: plus one untimed warm-up), ${W}x${H}, $THREADS threads, $REPEAT run(s) a side, alternating"
echo "* subfield: $SUBFIELD ($("$SUBFIELD" --version 2>/dev/null || echo '?')), \`subfield render SCENE --frames $F0..$F1 --size ${W}x${H} --max-depth 1 --threads $THREADS${IN_FLIGHT:+ --frames-in-flight $IN_FLIGHT} --stats\` (static part baked in memory; frame = update + trace + shade of the CSV; wall = the whole command / frames, import and bake included)"
((EMBREE)) && echo "* Embree: $(python3 -c 'import embreex; print("embreex", embreex.__version__)'), embree_anchor.py$( ((EQUAL)) && echo ' --whitted') (two-level, per-frame rebuild; frame = eval + update + trace, no shading, no image)"
if ((EQUAL)); then
    echo "* equal work: every material a half mirror (glb_material.py 0.5 0.0), Embree --whitted; camera $CAMERA"
else
    echo "* UNEQUAL work (--own-materials): the generator's materials, Embree without --whitted traces more rays than subfield; camera $CAMERA"
fi
((BLENDER)) && echo "* Blender: $(blender --version 2>/dev/null | head -n1), Cycles CPU, 1 spp, 1 glossy/transmission bounce, no diffuse bounce, no denoising, persistent data, EXR with Z (blender_peer.py; per-frame time of bpy.ops.render.render)"


status=0
scenes=()
IFS=, read -r -a configs <<< "$CONFIGS"
for c in "${configs[@]}"; do
    [[ "$c" =~ ^([0-9]+):([0-9]+):([0-9]+)$ ]] || die "--configs takes STATIC:DYNAMIC:SEED (got $c)"
    mat=own; ((EQUAL)) && mat=halfmirror
    scene="$OUT/gen_${BASH_REMATCH[1]}_${BASH_REMATCH[2]}_s${BASH_REMATCH[3]}_${CAMERA}_${mat}.glb"
    if [ ! -f "$scene" ]; then
        python3 "$PEERS/gen_scene.py" --static-tris "${BASH_REMATCH[1]}" \
            --dynamic-tris "${BASH_REMATCH[2]}" --frames 300 --fps 30 --seed "${BASH_REMATCH[3]}" \
            --camera-path "$CAMERA" --out "$scene.tmp.glb" >"$scene.log" 2>&1 &&
        { ((EQUAL == 0)) || python3 "$PEERS/glb_material.py" "$scene.tmp.glb" 0.5 0.0 >>"$scene.log" 2>&1; } &&
        mv "$scene.tmp.glb" "$scene" || { echo "skipped $c: gen_scene.py or glb_material.py failed: $(tail -n1 "$scene.log")"; status=1; continue; }
    fi
    scenes+=("$scene:morph")
done
if [ "$SKINNED" != none ]; then
    [[ "$SKINNED" =~ ^([0-9]+):([0-9]+)$ ]] || die "--skinned takes JOINTS:TRIS or none (got $SKINNED)"
    j=${BASH_REMATCH[1]}; tubes=$(( j >= 8 ? j / 8 : 1 )); per=$(( j / tubes ))
    scene="$OUT/skinned_${j}_${BASH_REMATCH[2]}.glb"
    python3 benches/skinned_scene.py --tubes "$tubes" --joints "$per" \
        --triangles "${BASH_REMATCH[2]}" --out "$scene" >"$scene.log" 2>&1 ||
        { echo "skipped the skinned scene: $(tail -n1 "$scene.log")"; status=1; }
    [ -f "$scene" ] && scenes+=("$scene:skin")
fi

for entry in "${scenes[@]}"; do
    scene=${entry%:*}; kind=${entry##*:}; tag=$(basename "$scene" .glb)
    echo
    echo "## $tag"
    echo
    run_subfield() {
        echo >&2 "$tag: subfield (run $1 of $REPEAT) ..."
        local csv="$OUT/$tag.subfield.$1.csv" t0 t1
        rm -rf "$OUT/$tag.frames"
        t0=$(date +%s.%N)
        "$SUBFIELD" render "$scene" -o "$OUT/$tag.frames/frame.####.exr" \
            --frames "$F0..$F1" --size "${W}x${H}" --max-depth 1 --threads "$THREADS" "${in_flight[@]}" \
            --stats "$csv" --quiet >"$OUT/$tag.subfield.err" 2>&1 ||
            { echo "skipped: subfield render failed: $(tail -n1 "$OUT/$tag.subfield.err")"; return 1; }
        t1=$(date +%s.%N)
        echo "$t0 $t1" >"$OUT/$tag.subfield.$1.wall"
    }
    run_embree() {
        [ "$kind" = morph ] && ((EMBREE)) || return 0
        echo >&2 "$tag: Embree (run $1 of $REPEAT) ..."
        local whitted=(); ((EQUAL)) && whitted=(--whitted)
        python3 "$PEERS/embree_anchor.py" "$scene" --frames "$F0:$F1:1" --width "$W" --height "$H" \
            --threads "$THREADS" "${whitted[@]}" >"$OUT/$tag.embree.$1.jsonl" 2>"$OUT/$tag.embree.err" ||
            { echo "skipped: the Embree harness failed: $(tail -n1 "$OUT/$tag.embree.err")"; return 1; }
    }
    run_blender() {
        ((BLENDER)) || return 0
        echo >&2 "$tag: Blender (run $1 of $REPEAT) ..."
        OMP_NUM_THREADS=$THREADS blender -b --factory-startup -t "$THREADS" --python "$PEERS/blender_peer.py" -- \
            "$scene" "$OUT/$tag.blender" "$F0" "$F1" "$W" "$H" 1 1 >"$OUT/$tag.blender.$1.log" 2>&1 ||
            { echo "skipped: Blender failed: $(tail -n1 "$OUT/$tag.blender.$1.log")"; return 1; }
    }
    ok=1
    for ((k = 1; k <= REPEAT; k++)); do
        if ((k % 2)); then
            run_embree "$k" && run_subfield "$k" && run_blender "$k" || { ok=0; break; }
        else
            run_blender "$k" && run_subfield "$k" && run_embree "$k" || { ok=0; break; }
        fi
    done
    ((ok)) || { status=1; continue; }
    python3 - "$OUT" "$tag" "$REPEAT" "$((F1 - F0))" <<'PY' || status=1
import csv, json, os, sys
from statistics import median

out, tag, repeat, nframes = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
runs = range(1, repeat + 1)
P = lambda *a: os.path.join(out, tag + "." + ".".join(map(str, a)))

def subfield(k):
    rows = list(csv.DictReader(open(P("subfield", k, "csv"))))
    if len(rows) != nframes:
        sys.exit(f"{P('subfield', k, 'csv')}: {len(rows)} rows, {nframes} frames asked")
    f = lambda r, *ks: sum(float(r[x]) for x in ks)
    frame = [f(r, "update_ms", "trace_ms", "shade_ms") for r in rows]
    t0, t1 = map(float, open(P("subfield", k, "wall")).read().split())
    return {"frame": frame, "update": [f(r, "update_ms") for r in rows],
            "trace": [f(r, "trace_ms") for r in rows], "shade": [f(r, "shade_ms") for r in rows],
            "write": [f(r, "write_ms") for r in rows], "wall": (t1 - t0) * 1e3 / nframes,
            "frames": [int(r["frame"]) for r in rows]}

def embree(k):
    path = P("embree", k, "jsonl")
    if not os.path.exists(path):
        return None
    fr = [j for j in map(json.loads, (l for l in open(path) if l.startswith("{")))
          if "frame" in j and not j.get("warmup")]
    return {"frame": [j["frame_ms"] for j in fr], "update": [j["eval_ms"] + j["update_ms"] for j in fr],
            "trace": [j["trace_ms"] for j in fr], "frames": [j["frame"] for j in fr]}

def blender(k):
    path = P("blender", k, "log")
    if not os.path.exists(path):
        return None
    fr = [j for j in map(json.loads, (l[l.index("{"):] for l in open(path) if l.lstrip().startswith('{"frame"')))]
    if not fr:
        print(f"Blender rendered no frame (see {path})")
        return None
    return {"frame": [j["s"] * 1e3 for j in fr], "frames": [j["frame"] for j in fr]}

S = [subfield(k) for k in runs]
E = [e for e in (embree(k) for k in runs) if e]
B = [b for b in (blender(k) for k in runs) if b]
mean = lambda v: sum(v) / len(v)
worst = lambda v: max(v)
arg = lambda v: v.index(max(v))
med = lambda side, key, f: median(f(r[key]) for r in side)
f1 = lambda x: f"{x:.1f}"
print("| side | ms/frame mean | ms/frame worst (frame) | update mean | update worst (frame) | trace mean | shade mean | write mean (writer thread) | wall ms/frame |")
print("|---|---|---|---|---|---|---|---|---|")
s = S[0]
print(f"| subfield render | {f1(med(S, 'frame', mean))} | {f1(med(S, 'frame', worst))} ({s['frames'][arg(s['frame'])]}) "
      f"| {f1(med(S, 'update', mean))} | {f1(med(S, 'update', worst))} ({s['frames'][arg(s['update'])]}) "
      f"| {f1(med(S, 'trace', mean))} | {f1(med(S, 'shade', mean))} | {f1(med(S, 'write', mean))} "
      f"| {f1(median(r['wall'] for r in S))} |")
if E:
    e = E[0]
    print(f"| Embree 4 (eval + update + trace) | {f1(med(E, 'frame', mean))} | {f1(med(E, 'frame', worst))} ({e['frames'][arg(e['frame'])]}) "
          f"| {f1(med(E, 'update', mean))} | {f1(med(E, 'update', worst))} ({e['frames'][arg(e['update'])]}) "
          f"| {f1(med(E, 'trace', mean))} | - | - | - |")
if B:
    b = B[0]
    print(f"| Blender Cycles | {f1(med(B, 'frame', mean))} | {f1(med(B, 'frame', worst))} ({b['frames'][arg(b['frame'])]}) | - | - | - | - | - | - |")
r = lambda a, b: f"{a / b:.2f}" if b else "n/a"
line = lambda side, key, f: ", ".join(r(f(a[key]), f(b[key])) for a, b in zip(S, side))
print()
if E:
    whole = ", ".join(r(a["wall"], mean(b["frame"])) for a, b in zip(S, E))
    print(f"**Whole subfield process (wall / frames) / Embree frame mean, run by run: {whole}** "
          "(the figure a user waits for; <= 1.0: subfield as fast or faster).")
    print(f"subfield / Embree, run by run: frame mean {line(E, 'frame', mean)}; frame worst {line(E, 'frame', worst)}; "
          f"update mean {line(E, 'update', mean)}; update worst {line(E, 'update', worst)} "
          "(<= 1.0: subfield as fast or faster; Embree's frame has no shading and no EXR).")
if B:
    print(f"subfield / Cycles, run by run: frame mean {line(B, 'frame', mean)}; frame worst {line(B, 'frame', worst)}.")
print(f"Medians of {len(S)} run(s) a side, {nframes} frames each.")
PY
done
echo
echo "* load after the run: $(uptime | sed 's/.*load average/load average/')"
exit $status
