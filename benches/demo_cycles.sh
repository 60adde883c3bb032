#!/usr/bin/env bash
# The demo against Blender Cycles (issue 23): the demo's museum (`subfield generate
# museum`), frames A..B at WxH, rendered by `subfield render` (defaults: 1 spp,
# --max-depth 4, the static part baked in memory) and by Cycles through
# ../shared/peers/blender_peer.py (CPU, 1 spp, no denoising, diffuse bounces 0,
# glossy/transmission 4, persistent data, EXR with Z), alternating which goes first,
# N runs a side. Prints each run's mean seconds a frame and the ratio; subfield's
# figure is update + trace + shade of its --stats (as Cycles' is its per-frame render
# time, import excluded), and its wall time a frame (import and bake included) beside.
#
#   benches/demo_cycles.sh [--frames A..B] [--size WxH] [--repeat N] [--out DIR]
set -euo pipefail
cd "$(dirname "$0")/.."

FRAMES=100..110
SIZE=640x480
REPEAT=2
OUT=target/demo-cycles
while [ $# -gt 0 ]; do
    case "$1" in
        --frames) FRAMES=${2:?}; shift ;;
        --size) SIZE=${2:?}; shift ;;
        --repeat) REPEAT=${2:?}; shift ;;
        --out) OUT=${2:?}; shift ;;
        -h|--help) sed -n '2,11p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "benches/demo_cycles.sh: unknown option $1" >&2; exit 2 ;;
    esac
    shift
done
[[ "$FRAMES" =~ ^([0-9]+)\.\.([0-9]+)$ ]] || { echo "--frames needs A..B" >&2; exit 2; }
F0=${BASH_REMATCH[1]}; F1=${BASH_REMATCH[2]}
[[ "$SIZE" =~ ^([0-9]+)x([0-9]+)$ ]] || { echo "--size needs WxH" >&2; exit 2; }
W=${BASH_REMATCH[1]}; H=${BASH_REMATCH[2]}
PEER=../shared/peers/blender_peer.py
[ -f "$PEER" ] || { echo "benches/demo_cycles.sh: $PEER not found (../shared is needed)" >&2; exit 1; }
command -v blender >/dev/null || { echo "benches/demo_cycles.sh: no blender (apt-get install blender)" >&2; exit 1; }

cargo build --release --quiet
bin=target/release/subfield
mkdir -p "$OUT"
"$bin" generate museum -o "$OUT/museum.glb" >/dev/null
echo "# $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "# $(blender --version 2>/dev/null | head -n1); subfield $(git rev-parse --short HEAD 2>/dev/null || echo ?)"
echo "# museum.glb frames $FRAMES at $SIZE"

subfield_run() {
    rm -rf "$OUT/sf"
    local t0 t1
    t0=$(date +%s.%N)
    "$bin" render "$OUT/museum.glb" -o "$OUT/sf/f.####.exr" --frames "$FRAMES" --size "$SIZE" \
        --stats "$OUT/sf.csv" --quiet
    t1=$(date +%s.%N)
    python3 - "$OUT/sf.csv" "$t0" "$t1" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
f = [float(r["update_ms"]) + float(r["trace_ms"]) + float(r["shade_ms"]) for r in rows]
wall = (float(sys.argv[3]) - float(sys.argv[2])) / len(rows)
print(f"{sum(f) / len(f) / 1e3:.4f} {wall:.4f}")
PY
}

cycles_run() {
    rm -rf "$OUT/cy"
    # blender_peer.py takes FIRST and LAST inclusive.
    blender -b --factory-startup --python "$PEER" -- "$OUT/museum.glb" "$OUT/cy" "$F0" "$((F1 - 1))" "$W" "$H" 1 4 2>/dev/null \
        | python3 -c 'import json, sys
for l in sys.stdin:
    l = l.strip()
    if l.startswith("{") and "summary" in l:
        print("%.4f" % json.loads(l)["summary"]["mean_frame_s"])'
}

for run in $(seq 1 "$REPEAT"); do
    if (( run % 2 )); then
        s=$(subfield_run); c=$(cycles_run)
    else
        c=$(cycles_run); s=$(subfield_run)
    fi
    read -r sf wall <<<"$s"
    python3 -c "import sys; s, w, c = map(float, sys.argv[1:]); print(f'run $run: subfield {s:.3f} s a frame (wall {w:.3f}), Cycles {c:.3f}: subfield / Cycles {s / c:.2f} (wall {w / c:.2f})')" "$sf" "$wall" "$c"
done
echo "# load after: $(cut -d' ' -f1-3 /proc/loadavg)"
