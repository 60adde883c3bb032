#!/usr/bin/env bash
# subfield against Intel Embree, side by side, on the same museum glTF files, same frames,
# same image size, same thread count, in one run (issue 8).
#
#   benches/embree.sh [--quick] [--frames A:B:S] [--width W] [--height H] [--threads T]
#                     [--configs STATIC:DYNAMIC,...] [--repeat N] [--out DIR]
#
# Defaults: 10284:1024,10284:16384,10284:100000,1000000:16384; frames 0:300:30 (10 frames,
# plus one untimed warm-up on each side); 640x480; threads = nproc. --quick: frames 0:90:30
# (3 frames) at 320x240. --repeat N: each side runs N times, alternating (Embree first in
# odd runs, subfield first in even ones); the table shows each side's median over its runs
# and the ratios of every pair of runs below it (a shared machine moves runs by 5-10%).
# Scenes and raw JSON lines go to DIR (default target/embree-bench).
#
# Needs python3 with embreex and numpy (pip install embreex numpy) and gcc (the harness
# compiles its small C tracing helper on first use). The harness is
# ../shared/peers/embree_anchor.py from the repository root (EMBREE_ANCHOR overrides).
set -euo pipefail
cd "$(dirname "$0")/.."

die() { echo "benches/embree.sh: $*" >&2; exit 1; }

FRAMES=0:300:30
WIDTH=640
HEIGHT=480
THREADS=$(nproc)
CONFIGS=10284:1024,10284:16384,10284:100000,1000000:16384
REPEAT=1
OUT=target/embree-bench
while [ $# -gt 0 ]; do
    case "$1" in
        --quick) FRAMES=0:90:30; WIDTH=320; HEIGHT=240 ;;
        --frames) FRAMES=${2:?--frames needs a value}; shift ;;
        --width) WIDTH=${2:?--width needs a value}; shift ;;
        --height) HEIGHT=${2:?--height needs a value}; shift ;;
        --threads) THREADS=${2:?--threads needs a value}; shift ;;
        --configs) CONFIGS=${2:?--configs needs a value}; shift ;;
        --repeat) REPEAT=${2:?--repeat needs a value}; shift ;;
        --out) OUT=${2:?--out needs a value}; shift ;;
        -h|--help) sed -n '2,17p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) die "unknown option $1 (see --help)" ;;
    esac
    shift
done

ANCHOR=${EMBREE_ANCHOR:-../shared/peers/embree_anchor.py}
command -v python3 >/dev/null || die "python3 is missing (the Embree harness is a Python script)"
command -v gcc >/dev/null || die "gcc is missing (the Embree harness compiles trace_helper.c with it)"
python3 -c "import embreex, numpy" 2>/dev/null ||
    die "python3 cannot import embreex and numpy: pip install embreex numpy"
[ -f "$ANCHOR" ] || die "the Embree harness $ANCHOR is not there (set EMBREE_ANCHOR)"
[[ "$REPEAT" =~ ^[1-9][0-9]*$ ]] || die "--repeat needs a whole number of runs, 1 or more (got $REPEAT)"
mkdir -p "$OUT"

echo "# subfield against Embree"
echo
echo "* machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
echo "* load before the run: $(uptime | sed 's/.*load average/load average/')"
echo "* frames $FRAMES (plus one untimed warm-up on each side), ${WIDTH}x${HEIGHT}, $THREADS threads on both sides, $REPEAT run(s) a side"
echo "* Embree: $(python3 -c 'import embreex; print("embreex", embreex.__version__)'), harness $ANCHOR (two-level, per-frame rebuild)"
echo "* subfield: static PSF baked once + dynamic layer updated per frame (cargo bench --bench embree)"

echo >&2 "building ..."
cargo build -q --release --bin subfield || die "cargo build failed"
cargo bench -q --bench embree --no-run || die "building benches/embree.rs failed"

status=0
IFS=, read -r -a configs <<< "$CONFIGS"
for c in "${configs[@]}"; do
    n=${c%%:*}; m=${c##*:}
    scene="$OUT/museum_${n}_${m}.glb"
    echo
    echo "## ${n} static + ${m} moving triangles"
    echo
    if ! ./target/release/subfield generate museum --static-tris "$n" --dynamic-tris "$m" \
            -o "$scene" >"$OUT/generate_${n}_${m}.log" 2>&1; then
        echo "skipped: generating the scene failed: $(tail -n1 "$OUT/generate_${n}_${m}.log")"
        status=1
        continue
    fi
    run_embree() {
        echo >&2 "$c: Embree (run $1 of $REPEAT) ..."
        python3 "$ANCHOR" "$scene" --frames "$FRAMES" --width "$WIDTH" --height "$HEIGHT" \
            --threads "$THREADS" >"$OUT/embree_${n}_${m}.$1.jsonl" 2>"$OUT/embree_${n}_${m}.err" ||
            { echo "skipped: the Embree harness failed: $(tail -n1 "$OUT/embree_${n}_${m}.err")"; return 1; }
    }
    run_subfield() {
        echo >&2 "$c: subfield (run $1 of $REPEAT) ..."
        RAYON_NUM_THREADS=$THREADS cargo bench -q --bench embree -- "$scene" --frames "$FRAMES" \
            --width "$WIDTH" --height "$HEIGHT" >"$OUT/subfield_${n}_${m}.$1.jsonl" \
            2>"$OUT/subfield_${n}_${m}.err" ||
            { echo "skipped: the subfield bench failed: $(tail -n1 "$OUT/subfield_${n}_${m}.err")"; return 1; }
    }
    ok=1; runs=()
    for ((k = 1; k <= REPEAT; k++)); do
        if ((k % 2)); then
            run_embree "$k" && run_subfield "$k" || { ok=0; break; }
        else
            run_subfield "$k" && run_embree "$k" || { ok=0; break; }
        fi
        runs+=("$OUT/embree_${n}_${m}.$k.jsonl" "$OUT/subfield_${n}_${m}.$k.jsonl")
    done
    if ((!ok)); then status=1; continue; fi
    python3 - "${runs[@]}" <<'PY' || status=1
import json, sys

def read(path):
    setup, frames, summary = None, [], None
    for line in open(path):
        line = line.strip()
        if not line.startswith("{"):
            continue
        j = json.loads(line)
        if "setup" in j: setup = j["setup"]
        elif "summary" in j: summary = j["summary"]
        elif "frame" in j and not j.get("warmup"): frames.append(j)
    if summary is None or not frames:
        sys.exit(f"{path}: no summary line or no timed frame")
    tot = lambda k: sum(f[k] for f in frames)
    return setup, summary, {k: tot(k) for k in ("primary_rays", "primary_hits", "dynamic_hits",
                                                 "shadow_occluded", "reflect_hits")}

from statistics import median

# Arguments: Embree's and subfield's JSON lines, run by run.
pairs = [(read(a), read(b)) for a, b in zip(sys.argv[1::2], sys.argv[2::2])]
KEYS = ("static_build_ms", "mean_eval_ms", "mean_update_ms", "mean_trace_ms", "mean_frame_ms",
        "primary_mrays_s", "shadow_mrays_s", "reflect_mrays_s")

def side(k):
    runs = [p[k] for p in pairs]
    setup, summary, totals = runs[0]
    if any(r[1]["frames"] != summary["frames"] or r[2] != totals for r in runs):
        print(f"WARNING: {('Embree', 'subfield')[k]}'s runs differ in frames or hit counts")
    return setup, {**summary, **{key: median(r[1][key] for r in runs) for key in KEYS}}, totals

sides = [("Embree 4", *side(0)), ("subfield", *side(1))]
(_, es, e, et), (_, ss, s, st) = sides
if (es["static_tris"], es["dynamic_tris"]) != (ss["static_tris"], ss["dynamic_tris"]):
    print(f"WARNING: the sides read different triangle counts: Embree {es['static_tris']} + "
          f"{es['dynamic_tris']}, subfield {ss['static_tris']} + {ss['dynamic_tris']}")
if e["frames"] != s["frames"] or et["primary_rays"] != st["primary_rays"]:
    print("WARNING: the sides traced different frame or primary ray counts")
f2 = lambda x: f"{x:.2f}"
print("| side | static build ms | eval ms/frame | update ms/frame | primary Mrays/s | shadow Mrays/s "
      "| reflection Mrays/s | ms/frame | update + trace ms/frame | primary hits | dynamic hits | shadows occluded | reflection hits |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
for name, _, m, t in sides:
    print(f"| {name} | {m['static_build_ms']:.0f} | {f2(m['mean_eval_ms'])} | {f2(m['mean_update_ms'])} "
          f"| {f2(m['primary_mrays_s'])} | {f2(m['shadow_mrays_s'])} | {f2(m['reflect_mrays_s'])} "
          f"| {f2(m['mean_frame_ms'])} | {f2(m['mean_update_ms'] + m['mean_trace_ms'])} | {t['primary_hits']} | {t['dynamic_hits']} "
          f"| {t['shadow_occluded']} | {t['reflect_hits']} |")
r = lambda a, b: f"{a / b:.2f}" if b else "n/a"
print(f"| subfield / Embree | {r(s['static_build_ms'], e['static_build_ms'])} "
      f"| {r(s['mean_eval_ms'], e['mean_eval_ms'])} | **{r(s['mean_update_ms'], e['mean_update_ms'])}** "
      f"| {r(s['primary_mrays_s'], e['primary_mrays_s'])} | {r(s['shadow_mrays_s'], e['shadow_mrays_s'])} "
      f"| {r(s['reflect_mrays_s'], e['reflect_mrays_s'])} | **{r(s['mean_frame_ms'], e['mean_frame_ms'])}** "
      f"| {r(s['mean_update_ms'] + s['mean_trace_ms'], e['mean_update_ms'] + e['mean_trace_ms'])} "
      f"| {r(st['primary_hits'], et['primary_hits'])} | {r(st['dynamic_hits'], et['dynamic_hits'])} "
      f"| {r(st['shadow_occluded'], et['shadow_occluded'])} | {r(st['reflect_hits'], et['reflect_hits'])} |")
print()
if len(pairs) > 1:
    ratio = lambda f: ", ".join(f"{f(b[1]) / f(a[1]):.2f}" for a, b in pairs)
    print(f"Medians of {len(pairs)} runs a side. Run by run, subfield / Embree: ms/frame "
          f"{ratio(lambda m: m['mean_frame_ms'])}; update {ratio(lambda m: m['mean_update_ms'])}; "
          f"update + trace {ratio(lambda m: m['mean_update_ms'] + m['mean_trace_ms'])}.")
    print()
print(f"{s['frames']} frames, {st['primary_rays'] // s['frames']} primary rays per frame. Time ratios "
      "(build, eval, update, ms/frame, update + trace): <= 1.0 means subfield is as fast or faster; Mrays/s ratios: "
      ">= 1.0 means subfield is faster. eval = posing the moving triangles (numpy on the Embree side); ms/frame = eval + update + trace.")
PY
done
echo
echo "* load after the run: $(uptime | sed 's/.*load average/load average/')"
exit $status
