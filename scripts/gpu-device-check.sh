#!/usr/bin/env bash
# The GPU tracer's checks on a machine with a real GPU (issue 36), as one prepared run:
# the exactness suite (tests/gpu_vs_brute.rs) and the benchmark (benches/gpu.rs), with
# Embree's harness on the same file and frames in the same run (benches/gpu.sh's steps);
# then the CPU path's scaling from 1 thread to all the host's cores (benches/scaling.sh,
# issue 38).
#
#   scripts/gpu-device-check.sh prepare   # here: release builds of both into .device/gpu/
#   scripts/gpu-device-check.sh run       # there: runs them, figures to $OUT (or .device/out)
#   QUICK=1 scripts/gpu-device-check.sh run   # here: every step at small sizes (lavapipe)
#
# `run` keeps to DEVICE_SECONDS (540 by default) in all, under the device's 600 s a
# command: give the device call a timeout_s of 600. What it writes comes back as two
# files (the device returns at most 8): $OUT/results.tgz and $OUT/summary.txt.
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
    # The device returns at most 8 files from $OUT: every figure goes to a working
    # folder, which is packed into $OUT/results.tgz after each step (so a run cut off
    # still returns what it had), beside $OUT/summary.txt, this output.
    final="${OUT:-.device/out}"
    mkdir -p "$final"
    out=$(mktemp -d /tmp/device-run.XXXXXX)
    pack() {
        tar -czf "$final/results.tgz.part" -C "$out" . && mv -f "$final/results.tgz.part" "$final/results.tgz"
    }
    exec > >(tee "$final/summary.txt") 2>&1
    # A step that fails says so and the run goes on: no step may end the device's one
    # run early (a `grep` that found no note did, in the first rehearsal). Whatever
    # ends the run, what it wrote is packed.
    set +e
    trap pack EXIT
    trap 'pack; exit 143' TERM INT
    # One budget for the whole run (the device's `run` allows 600 s a command): each
    # step's timeout is what it asks for or what is left, so a slow step shortens the
    # later ones instead of the run being cut off mid-step. DEVICE_SECONDS sets it.
    end=$((SECONDS + ${DEVICE_SECONDS:-540}))
    # `t WANT [KEEP]`: WANT seconds, or what is left after KEEP for the steps after it.
    # The GPU's steps keep RESERVE (180 s) for issue 38's CPU scaling runs, which
    # come last and need about that on 16 cores.
    t() {
        local left=$((end - SECONDS - ${2:-0}))
        if ((left < 10)); then echo 1; elif (($1 < left)); then echo "$1"; else echo "$left"; fi
    }
    keep=${RESERVE:-180}
    # QUICK=1: a rehearsal of every step at small sizes, on any Vulkan driver (lavapipe
    # here), to find a broken step before the device's one run.
    if [ -n "${QUICK:-}" ]; then
        bench_size=128x128 moving=16384 frames=0..4 nframes=4 sizes=160x120 hd=160x120
        threads="1,2" scale_frames=0:4 demo_frames=0..2 ndemo=2
    else
        bench_size=1024x1024 moving=16384,1048576 frames=0..60 nframes=60 sizes="640x480 1920x1080"
        hd=1920x1080 threads="1,2,4,8,$(nproc)" scale_frames=0:24 demo_frames=0..60 ndemo=60
    fi
    for f in .device/gl/*.deb; do [ -e "$f" ] && dpkg -x "$f" /; done
    ldconfig 2>/dev/null || true
    export XDG_RUNTIME_DIR=/tmp CI=1
    # The NVIDIA driver's Vulkan manifest where the loader does not look for it
    # (the device's README names this place).
    icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    if [ -f "$icd" ] && ! ls /usr/share/vulkan/icd.d/nvidia* /etc/vulkan/icd.d/nvidia* >/dev/null 2>&1; then
        export VK_DRIVER_FILES=$icd
    fi
    { nvidia-smi -L; echo "VK_DRIVER_FILES=${VK_DRIVER_FILES:-}"; nproc; } >"$out/gpu.txt" 2>&1 || true
    cat "$out/gpu.txt"
    # Exactness first: with CI set, no adapter is a failure, not a skip.
    timeout "$(t 240 "$keep")" .device/gpu/gpu_vs_brute --test-threads 1 >"$out/exactness.txt" 2>&1 &&
        echo "exactness: passed" || echo "exactness: FAILED (see exactness.txt)"
    tail -n 3 "$out/exactness.txt"
    pack
    # Then the figures: the museum class and 1M moving, a 1024x1024 camera (1 M rays).
    timeout "$(t 200 "$keep")" .device/gpu/gpu_bench --size "$bench_size" --moving "$moving" --frames 5 \
        >"$out/bench.md" 2>&1 && echo "bench: done" || echo "bench: FAILED"
    tail -n 20 "$out/bench.md"
    pack
    # The peers' museum file: Embree's harness and the same rays on both tracers.
    python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/whl/*.whl ||
        echo "embreex: not installed (a Python other than 3.12?)"
    export PYTHONPATH=/tmp/site PEER_BUILD_DIR=/tmp/peer
    mkdir -p /tmp/peer && cp .device/libtrace_helper.so /tmp/peer/
    python3 .device/peers/gen_scene.py --static-tris 10284 --dynamic-tris 16384 \
        --frames 300 --fps 30 --seed 1 --out /tmp/museum.glb >/dev/null
    timeout "$(t 120 "$keep")" python3 .device/peers/embree_anchor.py /tmp/museum.glb --frames 0:50:10 \
        --width "${bench_size%x*}" --height "${bench_size#*x}" --threads "$(nproc)" >"$out/embree.jsonl" 2>&1 &&
        echo "embree: done" || echo "embree: FAILED"
    tail -n 1 "$out/embree.jsonl"
    timeout "$(t 120 "$keep")" .device/gpu/gpu_bench --scene /tmp/museum.glb --size "$bench_size" --frames 5 \
        --step 10 >"$out/bench-museum.md" 2>&1 && echo "bench (museum.glb): done" ||
        echo "bench (museum.glb): FAILED"
    tail -n 8 "$out/bench-museum.md"
    pack
    # Whole frames (issue 37): the museum class in half mirrors (inside the GPU frame
    # path's subset; a fallback says so in its log), 60 frames, `--device gpu` against
    # the CPU path on all the host's cores, wall time of the whole process and --stats.
    cp /tmp/museum.glb /tmp/museum-hm.glb
    python3 .device/peers/glb_material.py /tmp/museum-hm.glb 0.5 0.0 >/dev/null
    # `gpu1`, `gpu4`: the GPU one and four frames at a time (`gpu` renders two at once,
    # its default).
    for size in $sizes; do
        for dev in gpu gpu1 gpu4 cpu; do
            t0=$(date +%s.%N)
            inflight=()
            case "$dev" in gpu1) inflight=(--frames-in-flight 1) ;; gpu4) inflight=(--frames-in-flight 4) ;; esac
            timeout "$(t 150 "$keep")" .device/gpu/subfield render /tmp/museum-hm.glb -o "/tmp/frames-$dev-$size/f.####.exr" \
                --frames "$frames" --size "$size" --max-depth 1 --device "${dev%[14]}" "${inflight[@]}" \
                --stats "$out/whole-$dev-$size.csv" >"$out/whole-$dev-$size.log" 2>&1 &&
                echo "whole frames, $dev, $size: $(echo "$(date +%s.%N) $t0 $nframes" | awk '{printf "%.1f ms a frame", ($1-$2)*1000/$3}')" ||
                echo "whole frames, $dev, $size: FAILED (see whole-$dev-$size.log)"
            grep -h "note:" "$out/whole-$dev-$size.log" | head -n 1 || true
        done
        cmp -s "/tmp/frames-gpu-$size/f.0003.exr" "/tmp/frames-gpu1-$size/f.0003.exr" &&
            echo "frames in flight, $size: the same bytes" || echo "frames in flight, $size: DIFFER"
        pack
    done
    # The bake's default level is 2 (issue 38, round 5: the CPU's point grids take most
    # rays, so level 3 stopped paying there); the GPU walks the subfields with every
    # ray, so level 3 beside it, 60 frames at 1920x1080.
    for lv in 2 3; do
        .device/gpu/subfield bake /tmp/museum-hm.glb -o "/tmp/museum-l$lv.psf" --levels "$lv" -q >"$out/bake-$lv.log" 2>&1 || true
        t0=$(date +%s.%N)
        timeout "$(t 90 "$keep")" .device/gpu/subfield render /tmp/museum-hm.glb --baked "/tmp/museum-l$lv.psf" \
            -o "/tmp/frames-l$lv/f.####.exr" --frames "$frames" --size "$hd" --max-depth 1 \
            --device gpu --stats "$out/level-$lv.csv" >"$out/level-$lv.log" 2>&1 &&
            echo "level $lv on the GPU, $hd: $(echo "$(date +%s.%N) $t0 $nframes" | awk '{printf "%.1f ms a frame", ($1-$2)*1000/$3}')" ||
            echo "level $lv on the GPU: FAILED (see level-$lv.log)"
    done
    pack
    # The demo (glossy marble, glass, mirrors, depth 4: wholly on the GPU frame path),
    # 60 frames at 640x480, on each device.
    for dev in gpu cpu; do
        t0=$(date +%s.%N)
        timeout "$(t 90 "$keep")" .device/gpu/subfield demo -o "/tmp/demo-$dev" --frames "$demo_frames" --device "$dev" \
            >"$out/demo-$dev.log" 2>&1 &&
            echo "demo, $dev: $(echo "$(date +%s.%N) $t0 $ndemo" | awk '{printf "%.1f ms a frame", ($1-$2)*1000/$3}')" ||
            echo "demo, $dev: FAILED (see demo-$dev.log)"
        grep -h "note:\|per frame" "$out/demo-$dev.log" | head -n 2 || true
    done
    pack
    # The CPU path on all the host's cores against Embree, equal work (issue 38): 1 to 16
    # threads at 640x480, 1 and 16 at 1920x1080, both cameras; benches/efficiency.py on
    # the 1- and all-thread runs says where the cores wait.
    export SUBFIELD=.device/gpu/subfield PEERS=.device/peers
    timeout "$(t 300)" bash benches/scaling.sh --threads "$threads" --frames "$scale_frames" \
        --out /tmp/scaling >"$out/scaling.md" 2>"$out/scaling.err" &&
        echo "scaling: done" || echo "scaling: FAILED (see scaling.err)"
    cat "$out/scaling.md"
    pack
    timeout "$(t 200)" bash benches/scaling.sh --threads "1,$(nproc)" --frames "$scale_frames" --size "$hd" \
        --out /tmp/scaling-hd >"$out/scaling-hd.md" 2>>"$out/scaling.err" &&
        echo "scaling ($hd): done" || echo "scaling ($hd): FAILED"
    tail -n 6 "$out/scaling-hd.md"
    # The rows above render as many frames at once as the render chooses at each thread
    # count (--frames-in-flight left out); one frame at a time on 1 and on all cores beside
    # them, which is also what benches/efficiency.py reads (frames in flight overlap
    # their phases; it refuses such CSVs): each phase's efficiency from 1 to all cores.
    timeout "$(t 150)" bash benches/scaling.sh --threads "1,$(nproc)" --frames "$scale_frames" --in-flight 1 \
        --out /tmp/scaling-one >"$out/scaling-one.md" 2>>"$out/scaling.err" &&
        echo "scaling (one frame in flight): done" || echo "scaling (one frame in flight): FAILED"
    tail -n 6 "$out/scaling-one.md"
    for cam in still dolly; do
        d=/tmp/scaling-one/frame_${cam}_t
        python3 benches/efficiency.py --predict "$(nproc)" "$(ls ${d}1/*.subfield.1.csv):$(ls ${d}1/*.subfield.1.wall)" \
            "$(ls ${d}$(nproc)/*.subfield.1.csv):$(ls ${d}$(nproc)/*.subfield.1.wall)" >"$out/efficiency-$cam.md" 2>&1 || true
        tail -n 4 "$out/efficiency-$cam.md"
    done
    (cd /tmp && find scaling scaling-hd scaling-one \( -name '*.csv' -o -name '*.wall' -o -name '*.md' \) -print0 |
        tar -czf "$out/scaling-runs.tgz" --null -T -) || true
    pack
    echo "figures: results.tgz ($(du -h "$final/results.tgz" | cut -f1)), this output: summary.txt"
    ;;
*)
    echo "usage: $0 prepare|run" >&2
    exit 2
    ;;
esac
