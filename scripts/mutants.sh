#!/usr/bin/env bash
# Does the brute-force property suite have teeth? Applies hand-written mutations of the
# tracer, one at a time, to a scratch copy of the tree and checks that
#     cargo test --release --test psf_vs_brute
# fails for each. Nothing in the working tree is changed.
#
#     scripts/mutants.sh            every mutation below
#     scripts/mutants.sh 1 3        only mutations 1 and 3
#     scripts/mutants.sh --list     the mutations, without running anything
#
# Prints one line a mutation (caught / SURVIVED / NOT APPLIED / DOES NOT BUILD) and a
# summary; exits 0 only when the unmutated suite passes and every mutation applied,
# built and was caught. The first run builds the release profile (some minutes on two
# cores); each mutation then rebuilds the crate and the test (about a minute or two).
# The scratch copy, its build and the logs live in target/mutants/.
#
# Why hand-written rather than `cargo mutants`: cargo-mutants generates well over a
# hundred mutants for these files, each a rebuild, hours on the two-core machines. Its
# run, where there is time for it (not part of CI):
#     cargo install cargo-mutants
#     cargo mutants --file src/psf/traverse.rs --file src/psf/bsp.rs \
#         --file src/geometry/triangle.rs -- --test psf_vs_brute
#
# A mutation whose pattern no longer matches (the code moved) is NOT APPLIED and fails
# the run: update the pattern with the code, so the check never silently stops checking.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"

# number | file | sed program | what it breaks
mutations=(
  "src/psf/traverse.rs|s/b\.t as f64 + slack <= t_exit/b.t as f64 <= t_exit/g|early exit without slack: a tile's walk stops as soon as the best hit lies before its exit, with no allowance for the hit's rounding"
  "src/psf/traverse.rs|s/if ascending { e\.zmin } else { e\.zmax }/if ascending { e.zmax } else { e.zmin }/|the BSP walk tests an entry in the slab holding its far end instead of its near one"
  "src/psf/bsp.rs|s/hdr\.slab_of(e\.zmin)\.\.=hdr\.slab_of(e\.zmax)/hdr.slab_of(e.zmin)..=hdr.slab_of(e.zmin)/g|an entry listed only in the first slab its depth range overlaps"
  "src/psf/grid.rs|s/let m = margin \* self\.inv_tile;/let m = 0.0 * margin * self.inv_tile;/|no raster margin: tiles are not grown by the rounding allowance"
  "src/geometry/triangle.rs|/^pub fn intersect_triangle/,/^}/s/t >= t_min \&\& t <= t_max/t >= t_min \&\& t < t_max/|the triangle test's t_max exclusive (a hit at the best t so far is refused, so ties no longer go to the lower triangle number)"
)

if [ "${1:-}" = "--list" ]; then
  for k in "${!mutations[@]}"; do
    IFS='|' read -r file _ what <<<"${mutations[$k]}"
    echo "$((k + 1)). $file: $what"
  done
  exit 0
fi
chosen=("$@")
[ ${#chosen[@]} -eq 0 ] && chosen=($(seq 1 ${#mutations[@]}))

# Its own target folder: the runs do not wait on (or block) the developer's cargo, and
# the scratch crate's rebuilds leave target/release alone.
export CARGO_TARGET_DIR="$root/target/mutants/target"
export CARGO_TERM_COLOR=never
scratch="$root/target/mutants/tree"
log_dir="$root/target/mutants/logs"
mkdir -p "$scratch" "$log_dir"
# The tree as it is now (committed or not), without build outputs or git. Every file
# gets the time of the copy (tar -m): with the originals' older times, cargo would take
# a crate built from the last run's last mutation for up to date.
tar -C "$root" --exclude=./target --exclude=./.git --exclude=./fuzz/target -cf - . |
  tar -C "$scratch" -xmf -
cd "$scratch"

test_cmd=(cargo test --release --test psf_vs_brute)
limit=900 # seconds a mutated run may take before it counts as caught (a hang)

echo "baseline: ${test_cmd[*]} (unmutated)"
if ! "${test_cmd[@]}" >"$log_dir/baseline.log" 2>&1; then
  echo "error: the unmutated suite fails; see $log_dir/baseline.log" >&2
  tail -20 "$log_dir/baseline.log" >&2
  exit 1
fi
echo "baseline: passes ($(grep -Eo '[0-9]+ passed' "$log_dir/baseline.log" | head -1))"

caught=0
bad=0
for k in "${chosen[@]}"; do
  entry="${mutations[$((k - 1))]:-}"
  if [ -z "$entry" ]; then
    echo "error: no mutation $k (see --list)" >&2
    exit 2
  fi
  IFS='|' read -r file prog what <<<"$entry"
  cp "$root/$file" "$scratch/$file"
  sed -i -e "$prog" "$scratch/$file"
  log="$log_dir/mutation-$k.log"
  if cmp -s "$root/$file" "$scratch/$file"; then
    echo "$k. NOT APPLIED ($file: the pattern no longer matches): $what"
    bad=$((bad + 1))
    continue
  fi
  diff -u "$root/$file" "$scratch/$file" >"$log" || true
  if ! "${test_cmd[@]}" --no-run >>"$log" 2>&1; then
    echo "$k. DOES NOT BUILD ($file; see $log): $what"
    bad=$((bad + 1))
  else
    set +e
    timeout "$limit" "${test_cmd[@]}" >>"$log" 2>&1
    rc=$?
    set -e
    if [ "$rc" -eq 0 ]; then
      echo "$k. SURVIVED ($file): $what"
      bad=$((bad + 1))
    else
      how=$(grep -E '^test .* FAILED$' "$log" | sed -E 's/^test (.*) \.\.\. FAILED$/\1/' |
        paste -sd, - || true)
      [ "$rc" -eq 124 ] && how="timed out after ${limit}s"
      echo "$k. caught ($file; failed: ${how:-see $log}): $what"
      caught=$((caught + 1))
    fi
  fi
  # Restore (a fresh copy, so the next build sees the file changed back).
  cp "$root/$file" "$scratch/$file"
done

echo "mutations: ${#chosen[@]}, caught: $caught, not caught or not run: $bad (logs in $log_dir)"
[ "$bad" -eq 0 ]
