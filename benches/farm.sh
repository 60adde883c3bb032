#!/usr/bin/env bash
# The farm against one machine: 60 frames of the demo scene at 640x480, one local
# `subfield render` on 2 threads against a 2-task Slurm array (1 CPU each) on the
# one-node cluster of scripts/slurm-up.sh, in one run. Prints both wall times, each
# task's start-up (staging the bake, importing the scene, opening the bake) and its share
# of the task, and what staging costs against mapping the shared file in place.
#
#   benches/farm.sh [--frames A..B] [--size WxH] [--keep DIR]
#
# Not a test: it takes about two minutes on 2 cores. Needs root (the cluster).
set -euo pipefail
cd "$(dirname "$0")/.."

frames=0..60
size=640x480
keep=""
while [ $# -gt 0 ]; do
    case "$1" in
        --frames) frames=$2; shift 2 ;;
        --size) size=$2; shift 2 ;;
        --keep) keep=$2; shift 2 ;;
        -h|--help) sed -n '2,10p' "$0"; exit 0 ;;
        *) echo "benches/farm.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done

cargo build --release --quiet
bash scripts/slurm-up.sh
bin=$PWD/target/release/subfield
work=${keep:-$(mktemp -d /tmp/subfield-farm-bench.XXXXXX)}
mkdir -p "$work"
[ -n "$keep" ] || trap 'rm -rf "$work"' EXIT
now() { date +%s.%N; }
secs() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", b - a }'; }

"$bin" generate museum -o "$work/museum.glb" --quiet
"$bin" bake "$work/museum.glb" -o "$work/museum.psf" --quiet >/dev/null
bytes=$(stat -c %s "$work/museum.psf")

# Staging against mapping in place: the same 4 frames, bake mapped from the shared path,
# then staged into an empty stage, then from the warm stage (cached, verified).
t0=$(now); "$bin" render "$work/museum.glb" --baked "$work/museum.psf" -o "$work/m/f.####.exr" --frames 0..4 --size "$size" --quiet; t1=$(now)
"$bin" render "$work/museum.glb" --baked "$work/museum.psf" --stage-dir "$work/stage0" -o "$work/s/f.####.exr" --frames 0..4 --size "$size" --quiet; t2=$(now)
"$bin" render "$work/museum.glb" --baked "$work/museum.psf" --stage-dir "$work/stage0" -o "$work/w/f.####.exr" --frames 0..4 --size "$size" --quiet; t3=$(now)
cmp -s "$work/m/f.0003.exr" "$work/s/f.0003.exr" || { echo "staged frame differs" >&2; exit 1; }

t0l=$(now)
"$bin" render "$work/museum.glb" --baked "$work/museum.psf" -o "$work/local/f.####.exr" --frames "$frames" --size "$size" --threads 2 --quiet
t1l=$(now)

t0f=$(now)
id=$("$bin" submit slurm "$work/museum.glb" --baked "$work/museum.psf" -o "$work/farm/f.####.exr" \
    --frames "$frames" --size "$size" --tasks 2 --cpus-per-task 1 --stage-dir "$work/stage" --wait --quiet)
t1f=$(now)

for f in "$work"/local/*.exr; do
    cmp -s "$f" "$work/farm/$(basename "$f")" || { echo "farm frame $(basename "$f") differs from the local one" >&2; exit 1; }
done

echo "subfield farm bench: $(git rev-parse --short HEAD), $(nproc) cores, frames $frames at $size, bake $bytes bytes"
echo "mapping the shared bake in place vs staging (4 frames): in place $(secs "$t0" "$t1") s, staged cold $(secs "$t1" "$t2") s, staged warm $(secs "$t2" "$t3") s"
local_s=$(secs "$t0l" "$t1l")
farm_s=$(secs "$t0f" "$t1f")
echo "local render, 2 threads:        $local_s s"
echo "2-task Slurm array, 1 CPU each: $farm_s s (submit to last frame, job $id)  ratio $(awk -v a="$farm_s" -v b="$local_s" 'BEGIN { printf "%.3f", a / b }')"
for log in "$work"/farm/f.logs/"${id}"_*.log; do
    awk -v name="$(basename "$log")" '
        /^staged / { match($0, /in [0-9.]+ s\)/); stage = substr($0, RSTART + 3, RLENGTH - 6) }
        /^imported / { imp = $(NF - 1) }
        /^static part:/ { open = $(NF - 1) }
        /^rendered / { match($0, /in [0-9.]+ s;/); wall = substr($0, RSTART + 3, RLENGTH - 6); n = $2 }
        END {
            start = stage + imp; total = start + wall
            printf "  task %s: %d frames, start-up %.3f s (staging %.3f, import %.3f, opening the bake %.3f of the render), task %.2f s, start-up share %.2f%%\n",
                name, n, start + open, stage, imp, open, total, 100 * (start + open) / total
        }' "$log"
done
