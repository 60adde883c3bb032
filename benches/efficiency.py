#!/usr/bin/env python3
"""Where the cores wait (issue 38): per-phase parallel efficiency of `subfield render` from
the `--stats` CSVs of one scene rendered at two thread counts, and what Amdahl's law
predicts for more cores.

    benches/efficiency.py A.csv:WALL_A B.csv:WALL_B [--predict 16]

Each argument is a `--stats` CSV of the same frames at one thread count (the `threads`
column says which) and, after a colon, the whole command's wall time in seconds (or a
file holding "t0 t1", as benches/frame.sh writes it). For each phase of a frame (update =
posing + insertion, trace, shade: the frame loop's wall times; write: the EXR encoding on
the writer thread, overlapping the next frame) it prints the median a frame at each count,
the speed-up between them, and the parallel efficiency (speed-up / thread ratio). From the
two it solves Amdahl's law, T(n) = T(1) (s + (1 − s)/n), for the serial share s of each
phase and predicts its time and speed-up at --predict threads. `cpu_ms` (the render
threads' CPU time over update + trace + shade) gives how busy the threads were: cpu_ms /
(frame wall × threads), 1.0 when every thread worked throughout.

The process's time outside the frame loop (import, bake, the last frame's write, start-up
and exit: wall − the sum of the frames' update + trace + shade) is reported on its own.
Frame 0 of a still camera is left out of the medians (it fills the static hits kept for
later frames); all frames count in the wall time. The phases are one frame's: render the
CSVs with `--frames-in-flight 1` (several frames in flight overlap their phases).
"""
import csv
import statistics
import sys


def load(arg):
    path, _, wall = arg.rpartition(":")
    if not path:
        sys.exit(f"{arg}: expected CSV:WALL")
    try:
        wall_s = float(wall)
    except ValueError:
        t0, t1 = map(float, open(wall).read().split())
        wall_s = t1 - t0
    rows = list(csv.DictReader(open(path)))
    if not rows:
        sys.exit(f"{path}: no frames")
    threads = {int(r["threads"]) for r in rows if r.get("threads")}
    if len(threads) != 1:
        sys.exit(f"{path}: the threads column is missing or varies ({threads})")
    # Frames rendered side by side (`--frames-in-flight` above 1, the render's own
    # choice from 2 threads on) each report their own phases, which then add up to more
    # than the whole command took: the per-frame figures below would mean nothing.
    phases = sum(float(r[k]) for r in rows for k in ("update_ms", "trace_ms", "shade_ms")) / 1e3
    if phases > wall_s * 1.02:
        sys.exit(f"{path}: its frames overlap (their update + trace + shade add up to {phases:.2f} s "
                 f"against {wall_s:.2f} s for the whole command): render it with --frames-in-flight 1 "
                 "(benches/scaling.sh --in-flight 1)")
    return path, threads.pop(), wall_s, rows


def med(rows, key):
    xs = [float(r[key]) for r in rows[1:] or rows if r.get(key)]
    return statistics.median(xs) if xs else float("nan")


def main():
    args = sys.argv[1:]
    predict = 16
    if "--predict" in args:
        i = args.index("--predict")
        predict = int(args[i + 1])
        del args[i : i + 2]
    if len(args) != 2:
        sys.exit(__doc__)
    (pa, na, wa, ra), (pb, nb, wb, rb) = sorted(map(load, args), key=lambda x: x[1])
    if na == nb:
        sys.exit("both CSVs have the same thread count")
    if len(ra) != len(rb):
        sys.exit(f"{pa} has {len(ra)} frames, {pb} {len(rb)}")
    frames = len(ra)
    ratio = nb / na

    def amdahl(ta, tb):
        # T(n) = T1 (s + (1 - s)/n): two points give T1 and s.
        # ta = T1 (s + (1-s)/na), tb = T1 (s + (1-s)/nb)
        a1, a2 = 1 - 1 / na, 1 - 1 / nb  # T(n) = T1 (1/n + s (1 - 1/n))
        # ta = T1/na + T1 s a1; tb = T1/nb + T1 s a2 -> solve for T1 and T1 s.
        det = (1 / na) * a2 - (1 / nb) * a1
        t1 = (ta * a2 - tb * a1) / det
        t1s = ((1 / na) * tb - (1 / nb) * ta) / det
        s = min(max(t1s / t1, 0.0), 1.0) if t1 > 0 else float("nan")
        return t1, s

    print(f"| phase | {na} thread(s), ms | {nb} threads, ms | speed-up | efficiency | serial share (Amdahl) | serial ms a frame | predicted at {predict}, ms | predicted speed-up over 1 |")
    print("|---|---|---|---|---|---|---|---|---|")
    rowsum = lambda rows: [sum(float(r[k]) for k in ("update_ms", "trace_ms", "shade_ms")) for r in rows]
    for name, key in (("update", "update_ms"), ("trace", "trace_ms"), ("shade", "shade_ms"), ("frame (update + trace + shade)", None), ("write (writer thread)", "write_ms")):
        if key:
            ta, tb = med(ra, key), med(rb, key)
        else:
            ta, tb = statistics.median(rowsum(ra)[1:] or rowsum(ra)), statistics.median(rowsum(rb)[1:] or rowsum(rb))
        sp = ta / tb if tb else float("nan")
        if key == "write_ms":
            # One writer thread whatever the count: serial by construction.
            print(f"| {name} | {ta:.1f} | {tb:.1f} | {sp:.2f} | (one thread) | 1 | {tb:.1f} | {tb:.1f} | 1 |")
            continue
        t1, s = amdahl(ta, tb)
        tp = t1 * (s + (1 - s) / predict)
        print(f"| {name} | {ta:.1f} | {tb:.1f} | {sp:.2f} | {sp / ratio:.2f} | {s:.2f} | {t1 * s:.1f} | {tp:.1f} | {t1 / tp:.2f} |")

    def busy(rows, n):
        fr = rowsum(rows)
        cpu = [float(r["cpu_ms"]) for r in rows if r.get("cpu_ms")]
        if len(cpu) != len(fr):
            return float("nan")
        return sum(cpu[1:] or cpu) / ((sum(fr[1:] or fr)) * n)

    print()
    for path, n, wall, rows in ((pa, na, wa, ra), (pb, nb, wb, rb)):
        loop = sum(rowsum(rows)) / 1e3
        print(f"* {n} thread(s): whole process {wall:.2f} s = {wall / frames * 1e3:.1f} ms a frame over {frames} frames; "
              f"outside the frame loop (import, bake, last write, start-up, exit) {wall - loop:.2f} s; "
              f"threads busy {busy(rows, n):.2f} of the frame loop's wall time (cpu_ms); {path}")


if __name__ == "__main__":
    main()
