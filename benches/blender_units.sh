#!/bin/sh
# Issue 35's acceptance figure: a scene made and exported by Blender with the glTF
# exporter's default lighting mode, rendered by subfield and by Cycles (direct light
# only), compared per material. Needs Debian's blender (3.4), the system python3 with
# OpenEXR and numpy, and a built subfield (cargo build --release).
# run: sh benches/blender_units.sh [OUT_DIR] [W H SPP]
set -e
out=${1:-target/blender_units}
w=${2:-320}; h=${3:-240}; spp=${4:-64}
bin=${SUBFIELD:-target/release/subfield}
mkdir -p "$out"
blender -b --factory-startup --python benches/blender_units.py -- "$out" "$w" "$h" "$spp" \
    > "$out/blender.log" 2>&1
"$bin" render "$out/scene.glb" -o "$out/ours.#.exr" --frames 0 --size "${w}x${h}" \
    --float --aov albedo --spp 16 --quiet
python3 benches/blender_units_compare.py "$out/ours.0.exr" \
    "$out/cycles_principled.exr" "$out/cycles_lambert.exr"
echo "the same scene exported in Blender's \"Unitless\" lighting mode:"
"$bin" render "$out/scene_unitless.glb" -o "$out/unitless.#.exr" --frames 0 \
    --size "${w}x${h}" --float --aov albedo --spp 16 --quiet
python3 benches/blender_units_compare.py "$out/unitless.0.exr" "$out/cycles_lambert.exr"
