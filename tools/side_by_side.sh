#!/bin/bash
# Side by side: the same inputs run with several feticontact binaries, interleaved
# (rep 1: every binary, rep 2: every binary, ...), so that drift of a shared machine hits
# all binaries alike. One JSON line per run on standard output: binary, input, wall time,
# and from report.json the timings' maxima over ranks (total, solve, factorization, dual
# setup), Hessian multiplications, outer iterations, coarse solves, status, KKT pass/fail.
#
#   tools/side_by_side.sh [--ranks P] [--reps R] [--dir DIR] [--abba] BIN [BIN ...] -- INPUT [INPUT ...]
#
# --abba: each repetition runs the binaries in order and then in reverse order (A B B A),
# so that a drift or an after-effect of the run before (caches, frequency) hits every binary
# alike; each binary then has 2R runs (folders ..._<rep>a and ..._<rep>b).
#
# Each run gets DIR/<binary name>_<input name>_<rep>/ (log.txt, time.txt, output/...), run
# from there so that the input's relative &output directory lands inside it.
# Example (docs/RESULTS.md, "Quiet machine, session 5"):
#   tools/side_by_side.sh --reps 3 --dir sbs old/feticontact new/feticontact -- \
#       inputs/weak/cube_h4_n64.nml inputs/weak/cube_h8_n64.nml
# Medians: /usr/bin/python3 (standard library only) over the JSON lines.
set -euo pipefail
ranks=2; reps=1; dir=side_by_side; bins=(); abba=0
while [ $# -gt 0 ]; do
  case "$1" in
    --ranks) ranks=$2; shift 2 ;;
    --reps) reps=$2; shift 2 ;;
    --dir) dir=$2; shift 2 ;;
    --abba) abba=1; shift ;;
    --) shift; break ;;
    -h|--help) sed -n '2,19p' "$0"; exit 0 ;;
    *) bins+=("$(realpath "$1")"); shift ;;
  esac
done
[ ${#bins[@]} -gt 0 ] && [ $# -gt 0 ] || { echo "usage: see $0 --help" >&2; exit 2; }
inputs=(); for i in "$@"; do inputs+=("$(realpath "$i")"); done
mkdir -p "$dir"; dir=$(realpath "$dir")
if [ "$(id -u)" = 0 ]; then export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1; fi
export OMPI_MCA_rmaps_base_oversubscribe=1
for input in "${inputs[@]}"; do
  for rep in $(seq 1 "$reps"); do
    order=("${bins[@]}"); suffix=("${bins[@]/*/}")
    if [ "$abba" = 1 ]; then
      order=(); suffix=()
      for bin in "${bins[@]}"; do order+=("$bin"); suffix+=(a); done
      for ((k = ${#bins[@]} - 1; k >= 0; k--)); do order+=("${bins[$k]}"); suffix+=(b); done
    fi
    for k in "${!order[@]}"; do
      bin=${order[$k]}
      tag=$(basename "$bin")    # a copy such as feticontact_<commit>, or <build dir>_feticontact
      [ "$tag" = feticontact ] && tag=$(basename "$(dirname "$(dirname "$bin")")")_$tag
      d="$dir/${tag}_$(basename "$input" .nml)_$rep${suffix[$k]}"; rm -rf "$d"; mkdir -p "$d"
      ( cd "$d" && /usr/bin/time -f "%e" -o time.txt mpirun -np "$ranks" "$bin" "$input" > log.txt 2>&1 ) || true
      /usr/bin/python3 - "$d" "$bin" "$input" <<'PY'
import glob, json, sys
d, binary, inp = sys.argv[1:4]
out = {"binary": binary, "input": inp.split("/")[-1], "wall": float(open(d + "/time.txt").read().split()[-1])}
reports = glob.glob(d + "/**/report.json", recursive=True)
if reports:
    r = json.load(open(reports[0])); s = r.get("solver", {}); tm = r.get("timings", {})
    g = lambda k: tm[k]["max"] if k in tm else None
    out.update(total=g("total"), solve=g("solve"), fact=g("factorization"), dual=g("dual setup"),
               hess=s.get("hessian_multiplications"), outer=s.get("outer_iterations"),
               coarse=s.get("coarse_solves"), status=s.get("status"), kkt=r.get("kkt", {}).get("passed"))
print(json.dumps(out), flush=True)
PY
    done
  done
done
