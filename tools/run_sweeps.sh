#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The ready set of sweeps (datasets/sweeps/*.json) and their report in docs/accuracy/:
#
#   tools/run_sweeps.sh [--work DIR] [--voxlight build/voxlight] [SWEEP.json ...]
#
# Runs `voxlight sweep` on each (results in WORK/NAME, default /tmp/voxlight-sweeps; the path-traced
# references are kept in WORK/cache, so a second run renders only the variants), then
# tools/sweep_report.py over all of them with --docs docs/accuracy. A sweep whose volume is absent
# (the real CT lives in ../shared/datasets) is skipped with a note. Regenerate the report when a
# method changes. A benchmark, not a test: its seconds depend on the machine and its load.
set -euo pipefail
cd "$(dirname "$0")/.."
work=/tmp/voxlight-sweeps
voxlight=build/voxlight
sweeps=()
while [ $# -gt 0 ]; do
  case $1 in
    --work) work=$2; shift 2 ;;
    --voxlight) voxlight=$2; shift 2 ;;
    -h|--help) sed -n '3,10p' "$0"; exit 0 ;;
    *) sweeps+=("$1"); shift ;;
  esac
done
[ ${#sweeps[@]} -gt 0 ] || sweeps=(datasets/sweeps/*.json)
[ -x "$voxlight" ] || { echo "run_sweeps.sh: $voxlight not built (cmake --build build)" >&2; exit 2; }
mkdir -p "$work"
dirs=()
for s in "${sweeps[@]}"; do
  name=$(basename "$s" .json)
  start=$SECONDS
  if ! "$voxlight" sweep "$s" --out "$work/$name" --cache "$work/cache" 2>"$work/$name.log"; then
    if grep -q "does not exist\|No such file" "$work/$name.log"; then
      echo "$name: skipped: $(tail -n 1 "$work/$name.log")" >&2
      continue
    fi
    cat "$work/$name.log" >&2
    exit 1
  fi
  echo "$name: $(grep -c '^\[' "$work/$name.log") variants in $((SECONDS - start)) s" >&2
  dirs+=("$work/$name")
done
/usr/bin/python3 tools/sweep_report.py "${dirs[@]}" --docs docs/accuracy
