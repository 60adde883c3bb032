#!/bin/sh
# Issue 35: bounce light beside Cycles. The scene of benches/blender_units.py (made and
# exported by Blender with the glTF exporter's defaults), rendered by Cycles with N
# diffuse bounces (Lambertian materials, no clamping) and by subfield with
# `--diffuse-bounces N` at the same sample count; compared per material mask, then the
# noise of subfield's estimate at several spp against its own high-spp render.
# Needs Debian's blender (3.4), python3 with OpenEXR and numpy, a built subfield.
# run: sh benches/blender_bounces.sh [OUT_DIR] [W H SPP BOUNCES]
set -e
out=${1:-target/blender_bounces}
w=${2:-200}; h=${3:-150}; spp=${4:-256}; n=${5:-1}
bin=${SUBFIELD:-target/release/subfield}
mkdir -p "$out"
blender -b --factory-startup --python benches/blender_units.py -- "$out" "$w" "$h" "$spp" "$n" \
    > "$out/blender.log" 2>&1
for s in 4 16 64 "$spp"; do
    "$bin" render "$out/scene.glb" -o "$out/ours_s$s.#.exr" --frames 0 --size "${w}x${h}" \
        --float --aov albedo --spp "$s" --diffuse-bounces "$n" --quiet
done
echo "subfield --diffuse-bounces $n --spp $spp against Cycles, $n diffuse bounce(s), $spp samples:"
python3 benches/blender_units_compare.py --bounces "$out/ours_s$spp.0.exr" "$out/cycles_lambert_b$n.exr"
"$bin" render "$out/scene.glb" -o "$out/ours_direct.#.exr" --frames 0 --size "${w}x${h}" \
    --float --aov albedo --spp 16 --quiet
echo "the share of direct light in subfield's picture (direct / direct + $n bounce(s)):"
python3 benches/blender_units_compare.py "$out/ours_direct.0.exr" "$out/ours_s$spp.0.exr"
echo "the noise of subfield's estimate (RMS of the difference to --spp $spp, relative to the mean):"
python3 benches/noise.py "$out/ours_s$spp.0.exr" "$out"/ours_s4.0.exr "$out"/ours_s16.0.exr "$out"/ours_s64.0.exr
echo "Cycles' noise at $spp samples against subfield at $spp (both unbiased: the difference's RMS bounds both):"
python3 benches/noise.py "$out/ours_s$spp.0.exr" "$out/cycles_lambert_b$n.exr"
