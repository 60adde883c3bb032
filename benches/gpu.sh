#!/usr/bin/env bash
# The GPU tracer beside the CPU tracer (all cores) and Intel Embree, on the same file, the
# same frames and the same rays, in one run (issue 36).
#
#   benches/gpu.sh [--size WxH] [--frames F] [--threads T] [--million] [--out DIR]
#
# 1. `../shared/peers/gen_scene.py` writes the museum class (10,284 static + 16,384
#    moving triangles; with --million also 1,048,576 moving, 5 keys);
# 2. Embree's harness (`embree_anchor.py --threads T`) traces its camera, shadow and
#    mirror rays at frames 0, 10, 20, ... (F frames), rebuilding the moving part each
#    frame;
# 3. `cargo bench --bench gpu -- --scene FILE` poses the same frames and traces the same
#    camera rays, a shadow ray to the same light and a mirror ray about the hit
#    triangle's normal from each hit, and as many random rays, on the CPU tracer and on
#    the GPU tracer (wall time with transfers; pass time by timestamp queries), every GPU
#    answer compared with the CPU's.
# Defaults: 640x480, 5 frames, T = nproc, DIR = target/gpu-bench. Needs python3 with
# embreex and numpy, gcc, and a Vulkan adapter (lavapipe on a machine without a GPU: its
# figures say only that the benchmark runs; keep --size small there).
set -euo pipefail
cd "$(dirname "$0")/.."

SIZE=640x480
FRAMES=5
THREADS=$(nproc)
MILLION=0
OUT=target/gpu-bench
while [ $# -gt 0 ]; do
    case "$1" in
        --size) SIZE=${2:?--size needs a value}; shift ;;
        --frames) FRAMES=${2:?--frames needs a value}; shift ;;
        --threads) THREADS=${2:?--threads needs a value}; shift ;;
        --million) MILLION=1 ;;
        --out) OUT=${2:?--out needs a value}; shift ;;
        -h|--help) sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "benches/gpu.sh: unknown argument $1" >&2; exit 2 ;;
    esac
    shift
done
PEERS=${PEERS:-../shared/peers}
W=${SIZE%x*}; H=${SIZE#*x}
mkdir -p "$OUT"
scenes=("$OUT/museum.glb")
[ -f "$OUT/museum.glb" ] || python3 "$PEERS/gen_scene.py" --static-tris 10284 \
    --dynamic-tris 16384 --frames 300 --fps 30 --seed 1 --out "$OUT/museum.glb" >/dev/null
if [ "$MILLION" = 1 ]; then
    [ -f "$OUT/million.glb" ] || python3 "$PEERS/gen_scene.py" --static-tris 10284 \
        --dynamic-tris 1048576 --frames $((10 * FRAMES)) --keys 5 --fps 30 --seed 1 \
        --out "$OUT/million.glb" >/dev/null
    scenes+=("$OUT/million.glb")
fi
cargo bench --bench gpu --no-run --quiet 2>/dev/null
echo "# $(date -u +%FT%TZ), $(nproc) cores, $SIZE, $FRAMES frames (0, 10, ...), $THREADS threads"
for s in "${scenes[@]}"; do
    echo
    echo "## $(basename "$s"): Embree 4 (embree_anchor.py --threads $THREADS, rebuild a frame)"
    python3 "$PEERS/embree_anchor.py" "$s" --frames "0:$((10 * FRAMES)):10" --width "$W" \
        --height "$H" --threads "$THREADS" >"$OUT/embree-$(basename "$s" .glb).jsonl"
    tail -n 1 "$OUT/embree-$(basename "$s" .glb).jsonl"
    echo
    echo "## $(basename "$s"): subfield, CPU tracer on $THREADS threads and the GPU tracer"
    RAYON_NUM_THREADS=$THREADS cargo bench --bench gpu --quiet -- --scene "$s" \
        --size "$SIZE" --frames "$FRAMES" --step 10
done
