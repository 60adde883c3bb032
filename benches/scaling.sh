#!/usr/bin/env bash
# How subfield and Embree scale with cores (issue 38): benches/frame.sh on equal work (half
# mirrors everywhere, Embree --whitted) at 1, 2, 4, 8, ... threads up to all the machine
# has, for a still and a dollying camera, one table at the end: the whole `subfield
# render` process a frame (wall / frames, import, bake and EXRs included), Embree's frame,
# their ratio, and each side's speed-up over its own 1-thread figure.
#
#   benches/scaling.sh [--threads 1,2,4,...] [--cameras still,dolly] [--frames A:B]
#                      [--size WxH] [--config STATIC:DYNAMIC:SEED] [--repeat N] [--out DIR]
#                      [--in-flight N]
#
# Defaults: powers of two up to nproc (and nproc itself), both cameras, frames 0:24,
# 640x480, 10284:16384:1 (the museum class), --repeat 1, frames in flight as the render
# chooses (--in-flight N: --frames-in-flight N at every thread count). Needs what frame.sh needs
# (python3 with embreex and numpy, gcc); Blender is not run. SUBFIELD=BINARY as in frame.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
die() { echo "benches/scaling.sh: $*" >&2; exit 1; }

n=$(nproc); THREADS=""; t=1
while ((t < n)); do THREADS+="$t,"; t=$((t * 2)); done; THREADS+="$n"
CAMERAS=still,dolly; FRAMES=0:24; SIZE=640x480; CONFIG=10284:16384:1; REPEAT=1
OUT=target/scaling-bench
IN_FLIGHT=""
while [ $# -gt 0 ]; do
    case "$1" in
        --threads) THREADS=${2:?--threads needs a list}; shift ;;
        --cameras) CAMERAS=${2:?--cameras needs a list}; shift ;;
        --frames) FRAMES=${2:?--frames needs A:B}; shift ;;
        --size) SIZE=${2:?--size needs WxH}; shift ;;
        --config) CONFIG=${2:?--config needs STATIC:DYNAMIC:SEED}; shift ;;
        --repeat) REPEAT=${2:?--repeat needs a number}; shift ;;
        --out) OUT=${2:?--out needs a folder}; shift ;;
        --in-flight) IN_FLIGHT=${2:?--in-flight needs a number}; shift ;;
        -h|--help) sed -n '2,15p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) die "unknown option $1 (see --help)" ;;
    esac
    shift
done
[[ "$THREADS" =~ ^[1-9][0-9]*(,[1-9][0-9]*)*$ ]] || die "--threads takes a comma list of whole numbers (got $THREADS)"
[[ "$CAMERAS" =~ ^(still|dolly)(,(still|dolly))*$ ]] || die "--cameras takes still and/or dolly (got $CAMERAS)"
mkdir -p "$OUT"
if [ -z "${SUBFIELD:-}" ]; then
    cargo build -q --release --bin subfield || die "cargo build failed"
    export SUBFIELD=./target/release/subfield
fi
export SUBFIELD

IFS=, read -r -a threads <<< "$THREADS"
IFS=, read -r -a cameras <<< "$CAMERAS"
rows="$OUT/rows.tsv"; : > "$rows"
for cam in "${cameras[@]}"; do
    for t in "${threads[@]}"; do
        echo >&2 "camera $cam, $t thread(s) ..."
        md="$OUT/frame_${cam}_t$t.md"
        bash benches/frame.sh --no-blender --skinned none --configs "$CONFIG" --frames "$FRAMES" \
            --size "$SIZE" --threads "$t" --repeat "$REPEAT" --camera "$cam" \
            ${IN_FLIGHT:+--in-flight "$IN_FLIGHT"} --out "$OUT/frame_${cam}_t$t" > "$md" || die "frame.sh failed for $cam at $t threads: see $md"
        # The table rows of frame.sh: subfield's wall ms a frame is the last column of its
        # row, Embree's frame mean the second column of its row.
        wall=$(awk -F'|' '/^\| subfield render/ {gsub(/ /,"",$10); print $10}' "$md")
        emb=$(awk -F'|' '/^\| Embree/ {gsub(/ /,"",$3); print $3}' "$md")
        [ -n "$wall" ] && [ -n "$emb" ] || die "no figures in $md"
        printf '%s\t%s\t%s\t%s\n' "$cam" "$t" "$wall" "$emb" >> "$rows"
    done
done

echo "# Scaling: whole subfield process against Embree's frame, equal work"
echo
echo "* machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//'); load after: $(uptime | sed 's/.*load average/load average/')"
echo "* scene $CONFIG, frames $FRAMES, $SIZE, --max-depth 1, $REPEAT run(s) a side (medians); per-run tables in $OUT/frame_*.md"
echo
echo "| camera | threads | subfield ms a frame (whole process) | Embree ms a frame | subfield / Embree | subfield speed-up over the first row | Embree speed-up over the first row |"
echo "|---|---|---|---|---|---|---|"
awk -F'\t' '
    !($1 in s1) { s1[$1] = $3; e1[$1] = $4 }
    { printf "| %s | %s | %.1f | %.1f | %.2f | %.2fx | %.2fx |\n", $1, $2, $3, $4, $3 / $4, s1[$1] / $3, e1[$1] / $4 }
' "$rows"
