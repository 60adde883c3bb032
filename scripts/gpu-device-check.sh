#!/usr/bin/env bash
# The GPU tracer's checks on a machine with a real GPU (issue 36), as one prepared run:
# the exactness suite (tests/gpu_vs_brute.rs) and the benchmark (benches/gpu.rs), with
# Embree's harness on the same file and frames in the same run (benches/gpu.sh's steps);
# then the CPU path's scaling from 1 thread to all the host's cores (benches/scaling.sh,
# issue 38).
#
#   scripts/gpu-device-check.sh prepare   # here: release builds of both into .device/gpu/
#   scripts/gpu-device-check.sh run       # there: runs them, figures to $OUT (or .device/out)
#
# `run` keeps to DEVICE_SECONDS (540 by default) in all, under the device's 600 s a
# command: give the device call a timeout_s of 600.
#
# `prepare` builds on this machine (the GPU machine may have no crates to build from);
# `run` needs a Vulkan loader there: unpack Debian's libvulkan1 first, as
# ../shared/peers/README.md shows (.device/gl/*.deb). Ignore .device/ in git
# (.gitignore lists it) and carry it along.
set -euo pipefail
cd "$(dirname "$0")/.."

case "${1:-}" in
prepare)
    mkdir -p .device/gpu
    test_exe=$(cargo test --release --test gpu_vs_brute --no-run --message-format=json 2>/dev/null |
        python3 -c 'import json,sys
for l in sys.stdin:
    m = json.loads(l)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["name"] == "gpu_vs_brute":
        print(m["executable"])')
    bench_exe=$(cargo bench --bench gpu --no-run --message-format=json 2>/dev/null |
        python3 -c 'import json,sys
for l in sys.stdin:
    m = json.loads(l)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["name"] == "gpu":
        print(m["executable"])')
    strip -o .device/gpu/gpu_vs_brute "$test_exe"
    strip -o .device/gpu/gpu_bench "$bench_exe"
    # The CPU path's scaling (issue 38) runs the release binary.
    cargo build -q --release --bin subfield
    strip -o .device/gpu/subfield target/release/subfield
    # The peers: the scene generator and Embree's harness, embreex for the machine's
    # Python 3.12, the harness's C helper built here (../shared/peers/README.md).
    peers=${PEERS:-../shared/peers}
    mkdir -p .device/whl .device/gl
    cp -r "$peers" .device/
    ls .device/whl/embreex-*.whl >/dev/null 2>&1 ||
        python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
            --implementation cp --platform manylinux_2_28_x86_64 -d .device/whl embreex==4.4.0.post1
    gcc -O3 -march=x86-64-v3 -shared -fPIC -pthread "$peers/trace_helper.c" \
        -o .device/libtrace_helper.so
    ls .device/gl/libvulkan1*.deb >/dev/null 2>&1 || {
        o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
        mkdir -p /tmp/amd64/partial && apt-get $o update -qq && (cd .device/gl && apt-get $o download libvulkan1)
    }
    du -sh .device
    ls -l .device/gpu
    ;;
run)
    out="${OUT:-.device/out}"
    # One budget for the whole run (the device's `run` allows 600 s a command): each
    # step's timeout is what it asks for or what is left, so a slow step shortens the
    # later ones instead of the run being cut off mid-step; the figures so far are in
    # $out either way. DEVICE_SECONDS sets the budget.
    end=$((SECONDS + ${DEVICE_SECONDS:-540}))
    t() {
        local left=$((end - SECONDS))
        if ((left < 10)); then echo 1; elif (($1 < left)); then echo "$1"; else echo "$left"; fi
    }
    mkdir -p "$out"
    for f in .device/gl/*.deb; do [ -e "$f" ] && dpkg -x "$f" /; done
    ldconfig 2>/dev/null || true
    export XDG_RUNTIME_DIR=/tmp CI=1
    nvidia-smi -L >"$out/gpu.txt" 2>&1 || true
    # Exactness first: with CI set, no adapter is a failure, not a skip.
    timeout "$(t 240)" .device/gpu/gpu_vs_brute --test-threads 1 >"$out/exactness.txt" 2>&1 &&
        echo "exactness: passed" || echo "exactness: FAILED (see $out/exactness.txt)"
    # Then the figures: the museum class and 1M moving, a 1024x1024 camera (1 M rays).
    timeout "$(t 200)" .device/gpu/gpu_bench --size 1024x1024 --moving 16384,1048576 --frames 5 \
        >"$out/bench.md" 2>&1 && echo "bench: done" || echo "bench: FAILED"
    tail -n 20 "$out/bench.md"
    # The peers' museum file: Embree's harness and the same rays on both tracers.
    python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/whl/*.whl
    export PYTHONPATH=/tmp/site PEER_BUILD_DIR=/tmp/peer
    mkdir -p /tmp/peer && cp .device/libtrace_helper.so /tmp/peer/
    python3 .device/peers/gen_scene.py --static-tris 10284 --dynamic-tris 16384 \
        --frames 300 --fps 30 --seed 1 --out /tmp/museum.glb >/dev/null
    timeout "$(t 120)" python3 .device/peers/embree_anchor.py /tmp/museum.glb --frames 0:50:10 \
        --width 1024 --height 1024 --threads "$(nproc)" >"$out/embree.jsonl" 2>&1 &&
        echo "embree: done" || echo "embree: FAILED"
    tail -n 1 "$out/embree.jsonl"
    timeout "$(t 120)" .device/gpu/gpu_bench --scene /tmp/museum.glb --size 1024x1024 --frames 5 \
        --step 10 >"$out/bench-museum.md" 2>&1 && echo "bench (museum.glb): done" ||
        echo "bench (museum.glb): FAILED"
    tail -n 8 "$out/bench-museum.md"
    # Whole frames (issue 37): the museum class in half mirrors (inside the GPU frame
    # path's subset; a fallback says so in its log), 60 frames, `--device gpu` against
    # the CPU path on all the host's cores, wall time of the whole process and --stats.
    cp /tmp/museum.glb /tmp/museum-hm.glb
    python3 .device/peers/glb_material.py /tmp/museum-hm.glb 0.5 0.0 >/dev/null
    # `gpu1`, `gpu4`: the GPU one and four frames at a time (`gpu` renders two at once,
    # its default).
    for size in 640x480 1920x1080; do
        for dev in gpu gpu1 gpu4 cpu; do
            t0=$(date +%s.%N)
            inflight=()
            case "$dev" in gpu1) inflight=(--frames-in-flight 1) ;; gpu4) inflight=(--frames-in-flight 4) ;; esac
            timeout "$(t 150)" .device/gpu/subfield render /tmp/museum-hm.glb -o "/tmp/frames-$dev-$size/f.####.exr" \
                --frames 0..60 --size "$size" --max-depth 1 --device "${dev%[14]}" "${inflight[@]}" \
                --stats "$out/whole-$dev-$size.csv" >"$out/whole-$dev-$size.log" 2>&1 &&
                echo "whole frames, $dev, $size: $(echo "$(date +%s.%N) $t0" | awk '{printf "%.1f ms a frame", ($1-$2)*1000/60}')" ||
                echo "whole frames, $dev, $size: FAILED (see $out/whole-$dev-$size.log)"
            grep -h "note:" "$out/whole-$dev-$size.log" | head -n 1
        done
        cmp -s "/tmp/frames-gpu-$size/f.0030.exr" "/tmp/frames-gpu1-$size/f.0030.exr" &&
            echo "frames in flight, $size: the same bytes" || echo "frames in flight, $size: DIFFER"
    done
    # The bake's default level is 2 (issue 38, round 5: the CPU's point grids take most
    # rays, so level 3 stopped paying there); the GPU walks the subfields with every
    # ray, so level 3 beside it, 60 frames at 1920x1080.
    for lv in 2 3; do
        .device/gpu/subfield bake /tmp/museum-hm.glb -o "/tmp/museum-l$lv.psf" --levels "$lv" -q || true
        t0=$(date +%s.%N)
        timeout "$(t 90)" .device/gpu/subfield render /tmp/museum-hm.glb --baked "/tmp/museum-l$lv.psf" \
            -o "/tmp/frames-l$lv/f.####.exr" --frames 0..60 --size 1920x1080 --max-depth 1 \
            --device gpu --stats "$out/level-$lv.csv" >"$out/level-$lv.log" 2>&1 &&
            echo "level $lv on the GPU, 1920x1080: $(echo "$(date +%s.%N) $t0" | awk '{printf "%.1f ms a frame", ($1-$2)*1000/60}')" ||
            echo "level $lv on the GPU: FAILED (see $out/level-$lv.log)"
    done
    # The demo (glossy marble, glass, mirrors, depth 4: wholly on the GPU frame path),
    # 60 frames at 640x480, on each device.
    for dev in gpu cpu; do
        t0=$(date +%s.%N)
        timeout "$(t 90)" .device/gpu/subfield demo -o "/tmp/demo-$dev" --frames 0..60 --device "$dev" \
            >"$out/demo-$dev.log" 2>&1 &&
            echo "demo, $dev: $(echo "$(date +%s.%N) $t0" | awk '{printf "%.1f ms a frame", ($1-$2)*1000/60}')" ||
            echo "demo, $dev: FAILED (see $out/demo-$dev.log)"
        grep -h "note:\|per frame" "$out/demo-$dev.log" | head -n 2
    done
    # The CPU path on all the host's cores against Embree, equal work (issue 38): 1 to 16
    # threads at 640x480, 1 and 16 at 1920x1080, both cameras; benches/efficiency.py on
    # the 1- and 2-thread runs says where the cores wait.
    export SUBFIELD=.device/gpu/subfield PEERS=.device/peers
    timeout "$(t 300)" bash benches/scaling.sh --threads "1,2,4,8,$(nproc)" --frames 0:24 \
        --out /tmp/scaling >"$out/scaling.md" 2>"$out/scaling.err" &&
        echo "scaling: done" || echo "scaling: FAILED (see $out/scaling.err)"
    cat "$out/scaling.md"
    timeout "$(t 200)" bash benches/scaling.sh --threads "1,$(nproc)" --frames 0:12 --size 1920x1080 \
        --out /tmp/scaling-hd >"$out/scaling-hd.md" 2>>"$out/scaling.err" &&
        echo "scaling (1920x1080): done" || echo "scaling (1920x1080): FAILED"
    tail -n 6 "$out/scaling-hd.md"
    # The rows above render as many frames at once as the render chooses at each thread
    # count (--frames-in-flight left out); one frame at a time on 1 and on all cores beside
    # them, which is also what benches/efficiency.py reads (frames in flight overlap
    # their phases; it refuses such CSVs): each phase's efficiency from 1 to all cores.
    timeout "$(t 150)" bash benches/scaling.sh --threads "1,$(nproc)" --frames 0:24 --in-flight 1 \
        --out /tmp/scaling-one >"$out/scaling-one.md" 2>>"$out/scaling.err" &&
        echo "scaling (one frame in flight): done" || echo "scaling (one frame in flight): FAILED"
    tail -n 6 "$out/scaling-one.md"
    for cam in still dolly; do
        d=/tmp/scaling-one/frame_${cam}_t
        python3 benches/efficiency.py --predict "$(nproc)" "$(ls ${d}1/*.subfield.1.csv):$(ls ${d}1/*.subfield.1.wall)" \
            "$(ls ${d}$(nproc)/*.subfield.1.csv):$(ls ${d}$(nproc)/*.subfield.1.wall)" >"$out/efficiency-$cam.md" 2>&1 || true
    done
    (cd /tmp && find scaling scaling-hd scaling-one \( -name '*.csv' -o -name '*.wall' -o -name '*.md' \) -print0 |
        tar -czf "$out/scaling-runs.tgz" --null -T -) || true
    ;;
*)
    echo "usage: $0 prepare|run" >&2
    exit 2
    ;;
esac
