#!/usr/bin/env bash
# The GPU tracer's checks on a machine with a real GPU (issue 36), as one prepared run:
# the exactness suite (tests/gpu_vs_brute.rs) and the benchmark (benches/gpu.rs).
#
#   scripts/gpu-device-check.sh prepare   # here: release builds of both into .device/gpu/
#   scripts/gpu-device-check.sh run       # there: runs them, figures to $OUT (or .device/out)
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
    ls -l .device/gpu
    ;;
run)
    out="${OUT:-.device/out}"
    mkdir -p "$out"
    for f in .device/gl/*.deb; do [ -e "$f" ] && dpkg -x "$f" /; done
    ldconfig 2>/dev/null || true
    export XDG_RUNTIME_DIR=/tmp CI=1
    nvidia-smi -L >"$out/gpu.txt" 2>&1 || true
    # Exactness first: with CI set, no adapter is a failure, not a skip.
    timeout 240 .device/gpu/gpu_vs_brute --test-threads 1 >"$out/exactness.txt" 2>&1 &&
        echo "exactness: passed" || echo "exactness: FAILED (see $out/exactness.txt)"
    # Then the figures: the museum class and 1M moving, a 1024x1024 camera (1 M rays).
    timeout 240 .device/gpu/gpu_bench --size 1024x1024 --moving 16384,1048576 --frames 5 \
        >"$out/bench.md" 2>&1 && echo "bench: done" || echo "bench: FAILED"
    tail -n 20 "$out/bench.md"
    ;;
*)
    echo "usage: $0 prepare|run" >&2
    exit 2
    ;;
esac
