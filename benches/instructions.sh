#!/usr/bin/env bash
# Instructions one frame takes, counted by callgrind: exact and the same run after run,
# where wall times on a shared machine drift by several per cent within the hour
# (benches/PERF.md, issue 38, round 9). Compare two builds by their counts first, then
# time the one that counts fewer. Each instruction is put on the innermost line of this
# crate it was inlined from, and the lines and files that ran the most are listed.
#
#   benches/instructions.sh [--binary B] [--scene S.glb] [--camera still|dolly]
#                           [--size WxH] [--frame N] [--only PATTERN] [--top K] [--sim]
#                           [--warm]
#
# Defaults: target/release/subfield; the museum class in half mirrors with a dollying
# camera (written as benches/scaling.sh writes it, by ../shared/peers, if missing);
# 320x240 (a quarter of 640x480: the trace and shading scale with the pixels, the grids'
# builds do not); frame 5, rendered alone, --max-depth 1, 1 thread; the render pass
# (PATTERN `*Frames*trace*`, the frame's pass: `render_pass_with` is inlined into it, so
# its own name counted nothing; `*ShadeContext*shade*` counts shading alone); the top 30
# lines. `--sim` adds callgrind's branch and cache simulation and prints their totals
# (mispredicted conditional branches, first-level data misses): a change can run fewer
# instructions and take longer (benches/PERF.md, issue 38, round 10), and these models
# of a simple predictor and cache say why only roughly, so time it either way.
# `--warm` counts frame N as a sequence renders it, after frame N-1 (N >= 1): the
# buffers a render keeps from frame to frame have grown by then, where a frame rendered
# alone also pays for growing them (57 M instructions of growth and copies in a 640x480
# dolly frame, 42 M of them in its shading: benches/PERF.md, issue 38, round 20). Two
# runs, frames N-1..N and N-1..N+1, and their difference, address by address; twice the
# time. Not for a still camera, whose frame N-1 works differently when frame N follows
# (it stops with a message).
# Needs valgrind (Debian's `valgrind`), addr2line (binutils) and python3.
set -euo pipefail
cd "$(dirname "$0")/.."
die() { echo "benches/instructions.sh: $*" >&2; exit 1; }

BIN=target/release/subfield; SCENE=""; CAMERA=dolly; SIZE=320x240; FRAME=5
ONLY='*Frames*trace*'; TOP=30; SIM=(); WARM=0
while [ $# -gt 0 ]; do
    case "$1" in
        --binary) BIN=${2:?--binary needs a path}; shift ;;
        --scene) SCENE=${2:?--scene needs a file}; shift ;;
        --camera) CAMERA=${2:?--camera needs still or dolly}; shift ;;
        --size) SIZE=${2:?--size needs WxH}; shift ;;
        --frame) FRAME=${2:?--frame needs a number}; shift ;;
        --only) ONLY=${2:?--only needs a pattern}; shift ;;
        --top) TOP=${2:?--top needs a number}; shift ;;
        --sim) SIM=(--branch-sim=yes --cache-sim=yes) ;;
        --warm) WARM=1 ;;
        -h|--help) sed -n '2,29p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) die "unknown option $1 (see --help)" ;;
    esac
    shift
done
[[ "$CAMERA" =~ ^(still|dolly)$ ]] || die "--camera takes still or dolly (got $CAMERA)"
[[ "$SIZE" =~ ^[1-9][0-9]*x[1-9][0-9]*$ ]] || die "--size takes WxH (got $SIZE)"
[[ "$FRAME" =~ ^[0-9]+$ ]] || die "--frame takes a whole number (got $FRAME)"
[[ "$TOP" =~ ^[1-9][0-9]*$ ]] || die "--top takes a whole number (got $TOP)"
((WARM == 0 || FRAME >= 1)) || die "--warm counts frame N after frame N-1: --frame must be 1 or more"
[ ${#SIM[@]} -eq 0 ] || ((WARM == 0)) || die "--sim and --warm do not go together (the simulations' totals are not differenced)"
[ -x "$BIN" ] || die "no binary at $BIN (cargo build --release, or --binary)"
command -v valgrind >/dev/null || die "valgrind is not installed (apt-get install valgrind)"
command -v addr2line >/dev/null || die "addr2line is not installed (apt-get install binutils)"

if [ -z "$SCENE" ]; then
    PEERS=${PEERS:-../shared/peers}
    SCENE=target/scaling-bench/instructions/gen_10284_16384_s1_${CAMERA}_halfmirror.glb
    if [ ! -f "$SCENE" ]; then
        [ -f "$PEERS/gen_scene.py" ] || die "no scene given and no $PEERS/gen_scene.py to write one"
        mkdir -p "$(dirname "$SCENE")"
        python3 "$PEERS/gen_scene.py" --static-tris 10284 --dynamic-tris 16384 --frames 300 \
            --fps 30 --seed 1 --camera-path "$CAMERA" --out "$SCENE.tmp.glb" >/dev/null
        python3 "$PEERS/glb_material.py" "$SCENE.tmp.glb" 0.5 0.0 >/dev/null
        mv "$SCENE.tmp.glb" "$SCENE"
    fi
fi
[ -f "$SCENE" ] || die "no scene at $SCENE"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# count OUT FIRST: callgrind's counts of rendering frames FIRST..FRAME+1 into OUT.
count() {
    rm -rf "$work/frames"
    valgrind --tool=callgrind --dump-instr=yes --toggle-collect="$ONLY" "${SIM[@]}" \
        --callgrind-out-file="$1" "$BIN" render "$SCENE" -o "$work/frames/f.####.exr" \
        --frames "$2..$((FRAME + 1))" --size "$SIZE" --max-depth 1 --threads 1 \
        >"$work/render.log" 2>&1 || { tail -n 5 "$work/render.log" >&2; die "the render failed under valgrind"; }
}
if ((WARM)); then
    count "$work/cold.out" "$((FRAME - 1))"
    # The same run without frame N: what it counts is taken off, address by address.
    FRAME=$((FRAME - 1)) count "$work/before.out" "$((FRAME - 1))"
    cp "$work/cold.out" "$work/cg.out"
    SUBTRACT="$work/before.out"
    what="frame $FRAME after frame $((FRAME - 1)) (warm)"
else
    count "$work/cg.out" "$FRAME"
    SUBTRACT=""
    what="frame $FRAME rendered alone"
fi

echo "# Instructions: $BIN, $(basename "$SCENE"), $what, $SIZE, --max-depth 1, 1 thread, counting $ONLY"
if [ ${#SIM[@]} -gt 0 ]; then
    echo
    grep -E "(Branches|Mispredicts|D1  misses|LLd misses):" "$work/render.log" | sed 's/^==[0-9]*== */    /'
fi
python3 - "$work/cg.out" "$BIN" "$TOP" "$(pwd)/src/" "$SUBTRACT" <<'EOF'
import collections, re, subprocess, sys

out, binary, top, ours, before = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5]
# Callgrind's format with --dump-instr: "fn=(id) name" opens a function's costs,
# "calls=" lines are followed by the call's inclusive cost (skipped: self costs only),
# cost lines are "ADDR LINE Ir" with addresses absolute, relative (+n, -n) or "*".
def read(path):
    cost = collections.Counter()
    last, skip = 0, False
    with open(path) as f:
        for line in f:
            if re.match(r"^c?fn=", line):
                continue
            if line.startswith("calls="):
                skip = True
                continue
            m = re.match(r"^(0x[0-9a-f]+|[+-]\d+|\*)\s+\S+\s+(\d+)", line)
            if not m:
                continue
            a = m.group(1)
            last = int(a, 16) if a.startswith("0x") else last + int(a) if a[0] in "+-" else last
            if skip:
                skip = False
                continue
            cost[last] += int(m.group(2))
    return cost
cost = read(out)
if before:
    # --warm: the run without the counted frame taken off. Its first frame is the same
    # work in both runs, so what is left is the counted frame's (a few thousand
    # instructions of the thread pool's own timing aside: the total is the difference, the
    # tables show no address below 0).
    cost.subtract(read(before))
total = sum(cost.values())
if before:
    # Where the first frame's work depends on what follows it (a still camera looks
    # ahead to keep its hits for the next frame), the runs' first frames differ and
    # the difference is no frame's count: much below 0 says so.
    below = -sum(c for c in cost.values() if c < 0)
    if below > 0.01 * max(total, 1):
        sys.exit(f"benches/instructions.sh: --warm: the two runs' first frames differ "
                 f"({below:,} instructions more without the counted frame), so their "
                 f"difference is not the frame's count (a still camera's frame looks ahead "
                 f"to the next): count it without --warm")
cost = collections.Counter({a: c for a, c in cost.items() if c > 0})
if total == 0:
    # A pattern that names no function the binary has (inlined away, renamed) counts
    # nothing; a table of zeros would read as a result.
    sys.exit("benches/instructions.sh: --only's pattern counted no instructions: no function "
             "of the binary matches it (look for the name with `nm -C BINARY | grep`)")
addrs = sorted(cost)
lines = subprocess.run(["addr2line", "-e", binary, "-i", "-a"], input="\n".join(hex(a) for a in addrs),
                       capture_output=True, text=True, check=True).stdout.splitlines()
by_line, by_file = collections.Counter(), collections.Counter()
chain, at = [], None
def settle():
    if at is None:
        return
    place = next((c for c in chain if c.startswith(ours)), chain[0] if chain else "?")
    place = re.sub(r" \(discriminator \d+\)", "", place).replace(ours, "src/")
    by_line[place] += cost[at]
    by_file[place.rsplit(":", 1)[0]] += cost[at]
for l in lines:
    if l.startswith("0x"):
        settle()
        at, chain = int(l, 16), []
    else:
        chain.append(l)
settle()
print(f"\n{total:,} instructions\n\n| share | instructions | file |\n|---|---|---|")
for k, v in by_file.most_common(12):
    print(f"| {100 * v / total:.1f} % | {v:,} | {k} |")
print("\n| share | instructions | line (innermost of this crate) |\n|---|---|---|")
for k, v in by_line.most_common(top):
    print(f"| {100 * v / total:.2f} % | {v:,} | {k} |")
EOF
