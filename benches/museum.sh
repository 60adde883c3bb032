#!/usr/bin/env bash
# The paper's experiment (Khanna et al., BART museum, 16,384 animated triangles, 300
# frames, 640x480, Whitted with shadows and reflections), reproduced:
#   benches/museum.sh [--frames A..B] [--out DIR]
# BART's public museum lacks animart7.aff, so `subfield generate animart` writes one
# (16,384 triangles, seed 1) beside a copy of the museum's files, and museum7.aff is
# rendered directly (AFF import). Prints frame-time statistics beside the paper's.
set -euo pipefail
cd "$(dirname "$0")/.."
frames="0..300"
out="target/museum-experiment"
while [ $# -gt 0 ]; do
  case "$1" in
    --frames) frames="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    *) echo "usage: benches/museum.sh [--frames A..B] [--out DIR]" >&2; exit 2 ;;
  esac
done
museum="../shared/scenes/bart/museum"
if [ ! -f "$museum/museum7.aff" ]; then
  echo "benches/museum.sh: $museum/museum7.aff not found (../shared is needed)" >&2
  exit 1
fi
cargo build --release --quiet
bin=target/release/subfield
rm -rf "$out"
mkdir -p "$out/scene" "$out/frames"
# A copy, not links: includes that leave the scene's folder through a symbolic link are
# refused (docs/INPUTS.md), and the museum's files are 5 MB.
cp -R "$museum"/. "$out/scene/"
rm -f "$out/scene/animart7.aff"
"$bin" generate animart --triangles 16384 --seed 1 -o "$out/scene/animart7.aff" --quiet
echo "# $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), load $(cut -d' ' -f1-3 /proc/loadavg)"
start=$(date +%s.%N)
"$bin" render "$out/scene/museum7.aff" -o "$out/frames/frame.####.exr" --frames "$frames" \
  --size 640x480 --stats "$out/stats.csv" --plot "$out/plot.svg" --quiet
end=$(date +%s.%N)
python3 - "$out/stats.csv" "$start" "$end" <<'PY'
import csv, math, sys
rows = list(csv.DictReader(open(sys.argv[1])))
wall = float(sys.argv[3]) - float(sys.argv[2])
t = [float(r["update_ms"]) + float(r["trace_ms"]) + float(r["shade_ms"]) for r in rows]
n = len(t)
mean = sum(t) / n
sd = math.sqrt(sum((x - mean) ** 2 for x in t) / n)
rays = sum(int(r["primary_rays"]) + int(r["shadow_rays"]) + int(r["secondary_rays"]) for r in rows)
upd = sum(float(r["update_ms"]) for r in rows) / n
print(f"\n{n} frames, {rays / n / 1e6:.2f} M rays a frame, update {upd:.1f} ms a frame\n")
print("| | average frame | maximum frame | std deviation | all frames |")
print("|---|---|---|---|---|")
print(f"| subfield (update + trace + shade) | {mean / 1e3:.2f} s | {max(t) / 1e3:.2f} s | {sd / 1e3:.2f} s | {sum(t) / 60e3:.2f} min ({wall / 60:.2f} min wall, writing overlapped) |")
print("| paper (Khanna et al., 2004 hardware) | 12.89 s | 38.88 s | 8.15 s | 64.49 min |")
PY
echo "plot: $out/plot.svg"
