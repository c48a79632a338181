#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Runs libFuzzer targets of fuzz/ for a bounded time each:
#
#   tools/fuzz.sh TARGET|all SECONDS [libFuzzer options...]
#
# e.g. `tools/fuzz.sh dicom 3600` or `tools/fuzz.sh all 20` (what .ci/run does). Builds the `fuzz`
# preset (clang-14, ASan+UBSan) if needed, makes the seed corpora with tools/make_fuzz_corpus.py,
# and keeps what the fuzzer learns in build-fuzz/corpus/TARGET (the next run starts from there).
# Findings (crash-*, timeout-*, oom-*, leak-*) land in build-fuzz/findings/TARGET/; reproduce one
# with `build-fuzz/fuzz/fuzz_TARGET FILE`. Runs at nice 19 with -timeout=5 (a hang) and
# -rss_limit_mb=2048 (the memory budget). Prints one summary line per target (executions, time,
# exec/s, findings) and exits non-zero if any target found something.
# VOXLIGHT_FUZZ_JOBS=N runs N targets at once (default 1).
# VOXLIGHT_FUZZ_YIELD=1 for a long run beside other work: nice 19 only orders processes inside one
# scheduler autogroup (Linux, /proc/sys/kernel/sched_autogroup_enabled), and a run started in its
# own session (setsid, nohup from another terminal) is a group of its own that took a full core
# from a benchmark beside it; this lowers the group's weight too. Not the default: it would lower
# the whole calling session (a CI job) with it.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${VOXLIGHT_FUZZ_YIELD:-0}" = 1 ] && [ -w /proc/self/autogroup ]; then
  echo 19 >/proc/self/autogroup 2>/dev/null || true
fi

targets_all=(nifti nifti_gz nrrd nrrd_detached metaimage metaimage_mhd vti raw dicom dicom_series scene session)
if [ $# -lt 2 ]; then
  echo "usage: tools/fuzz.sh TARGET|all SECONDS [libFuzzer options...]" >&2
  echo "targets: ${targets_all[*]}" >&2
  exit 2
fi
which=$1
seconds=$2
shift 2
if [ "$which" = all ]; then targets=("${targets_all[@]}"); else targets=("$which"); fi

build=build-fuzz
need_build=()
for t in "${targets[@]}"; do
  case " ${targets_all[*]} " in *" $t "*) ;; *) echo "tools/fuzz.sh: unknown target '$t' (${targets_all[*]})" >&2; exit 2 ;; esac
  need_build+=("fuzz_$t")
done
# One build at a time (flock): two runs started together rebuilt the same modules at once, and a
# fuzzer that loaded a module while the other build rewrote it fuzzed nothing (5 December).
if [ ! -f "$build/build.ninja" ]; then cmake --preset fuzz >/dev/null; fi
mkdir -p "$build"
flock "$build/.build.lock" nice -n 19 cmake --build --preset fuzz --target "${need_build[@]}" >/dev/null

# Seeds: voxlight's phantom writer needs a built CLI (any preset's).
seeds=$build/corpus-seeds
if [ ! -d "$seeds/scene" ] || [ ! -d "$seeds/session" ]; then
  voxlight=build/voxlight
  if [ ! -x "$voxlight" ]; then
    nice -n 19 cmake --build --preset fuzz --target voxlight >/dev/null
    voxlight=$build/voxlight
  fi
  ASAN_OPTIONS=detect_leaks=0 /usr/bin/python3 tools/make_fuzz_corpus.py "$seeds" --voxlight "$voxlight" >/dev/null
fi

dict_for() {
  case $1 in
    nifti|nifti_gz) echo fuzz/nifti.dict ;;
    nrrd|nrrd_detached) echo fuzz/nrrd.dict ;;
    metaimage|metaimage_mhd) echo fuzz/metaimage.dict ;;
    vti) echo fuzz/vti.dict ;;
    dicom|dicom_series) echo fuzz/dicom.dict ;;
    scene|session) echo fuzz/json.dict ;;
    *) echo "" ;;
  esac
}

run_one() {
  local t=$1
  shift
  local corpus=$build/corpus/$t findings=$build/findings/$t log=$build/findings/$t.log
  mkdir -p "$corpus" "$findings"
  local dict
  dict=$(dict_for "$t")
  local args=(-max_total_time="$seconds" -timeout=5 -rss_limit_mb=2048 -max_len=16384
              -detect_leaks=0 -print_final_stats=1 -artifact_prefix="$findings/")
  if [ -n "$dict" ]; then args+=(-dict="$dict"); fi
  # Leaks are not findings: VTK and GDCM keep process-wide singletons.
  local rc=0 start=$SECONDS
  # The targets' scratch directories (fuzz/fuzz_common.h: mkdtemp under $TMPDIR, removed at a
  # normal exit) go under one directory per run, removed below and by the trap when this script
  # is stopped: a fuzzer killed by a signal or a timeout leaves its own behind.
  local scratch
  scratch=$(mktemp -d "${TMPDIR:-/tmp}/voxlight-fuzz-run-$$-$t-XXXXXX")
  export TMPDIR=$scratch
  # allocator_release_to_os_interval_ms=-1: ASan returning freed pages to the OS (madvise) was
  # most of the system time and made a 0.1 s input time out on a loaded machine.
  # symbolize=0: a reader child (dicom_loader.cpp) that asks for more than -rss_limit_mb in one
  # malloc is stopped by libFuzzer's malloc hook, inherited across the fork, which printed a
  # symbolized stack: 0.7 s per such input alone, over the 5 s limit beside other work — every
  # long dicom_series run ended at such a "timeout" within minutes (5 December). Reports are
  # symbolized afterwards by running each finding again (below).
  ASAN_OPTIONS=detect_leaks=0:abort_on_error=1:symbolize=0:allocator_release_to_os_interval_ms=-1 \
  UBSAN_OPTIONS=print_stacktrace=1 \
    nice -n 19 "$build/fuzz/fuzz_$t" "${args[@]}" "$@" "$corpus" "$seeds/$t" >"$log" 2>&1 || rc=$?
  # A timeout under a loaded machine (nice 19) is confirmed by running the input again on its own:
  # one that then takes under the limit is set aside in unconfirmed/, not counted. The recheck
  # runs in a session of its own (setsid: its own autogroup, at the default weight), so that a
  # VOXLIGHT_FUZZ_YIELD run starved by other work does not confirm its own timeouts (two
  # dicom_series inputs of 0.2-0.3 s were, beside a two-thread benchmark).
  local f
  for f in $(find "$findings" -maxdepth 1 -type f -name 'timeout-*' -newer "$log.start"); do
    local rerun=0
    # Under the build lock (shared): no rebuild replaces a module while the recheck loads it. Its
    # own artifacts go to recheck/ (not the working directory, not counted again).
    mkdir -p "$findings/recheck"
    ASAN_OPTIONS=detect_leaks=0 flock -s "$build/.build.lock" setsid -w timeout 60 \
      "$build/fuzz/fuzz_$t" -timeout=5 -rss_limit_mb=2048 -artifact_prefix="$findings/recheck/" \
      "$f" >"$f.recheck.log" 2>&1 || rerun=$?
    if [ $rerun -eq 0 ]; then
      mkdir -p "$findings/unconfirmed"
      mv "$f" "$f.recheck.log" "$findings/unconfirmed/"
      echo "$t: $(basename "$f") ran in time when repeated alone: set aside in $findings/unconfirmed/" >&2
      [ $rc -eq 70 ] && rc=0
    elif ! grep -q '^Running: ' "$f.recheck.log"; then
      # The target stopped before it ran the input (a reader module that did not load, e.g. one
      # a parallel build was replacing): neither confirmed nor dismissed (5 December, a stale
      # module's abort at start confirmed a 0.46 s input as a timeout).
      mkdir -p "$findings/unconfirmed"
      mv "$f" "$f.recheck.log" "$findings/unconfirmed/"
      echo "$t: $(basename "$f"): the recheck did not run it (exit $rerun: $(head -n 1 \
        "$findings/unconfirmed/$(basename "$f").recheck.log")); set aside in $findings/unconfirmed/;" \
        "re-run it by hand" >&2
      # Not dismissed either: the run still fails (a timeout no one has checked must not pass CI).
    fi
  done
  local elapsed=$((SECONDS - start)) execs rate found
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
  found=$(find "$findings" -maxdepth 1 -type f -newer "$log.start" 2>/dev/null | wc -l)
  printf '%-14s %9s executions in %5s s, %6s exec/s, %d finding(s)%s\n' "$t" "${execs:-?}" \
    "$elapsed" "${rate:-?}" "$found" "$([ $rc -ne 0 ] && echo " (exit $rc; see $log)")"
  if [ $rc -ne 0 ] || [ "$found" -ne 0 ]; then
    # The log and the input stay in build-fuzz/ (gone with a CI machine): show what matters here,
    # the report and the input as hex, so a finding can be reproduced from the CI log alone.
    grep -v -E '^(#[0-9]+|INFO:|MS:|stat::|Dictionary:|Done )' "$log" | tail -n 40 | sed "s/^/  $t| /" >&2
    # The run's stacks are addresses (symbolize=0 above): each input again, symbolized.
    mkdir -p "$findings/recheck"
    for f in $(find "$findings" -maxdepth 1 -type f -newer "$log.start" ! -name '*.log' 2>/dev/null | head -n 3); do
      ASAN_OPTIONS=detect_leaks=0 flock -s "$build/.build.lock" timeout 120 \
        "$build/fuzz/fuzz_$t" -timeout=5 -rss_limit_mb=2048 -artifact_prefix="$findings/recheck/" \
        "$f" >"$f.report.log" 2>&1 || true
      echo "  $t| $(basename "$f") again, symbolized:" >&2
      grep -v -E '^(INFO:|Running:|Executed |\*\*\*)' "$f.report.log" | tail -n 40 | sed "s/^/  $t|   /" >&2
    done
    for f in $(find "$findings" -maxdepth 1 -type f -newer "$log.start" ! -name '*.log' 2>/dev/null | head -n 3); do
      echo "  $t| input $(basename "$f") ($(stat -c %s "$f") bytes), base64:" >&2
      head -c 16384 "$f" | base64 -w 120 | sed "s/^/  $t|   /" >&2
    done
  fi
  rm -rf "$scratch"
  [ $rc -eq 0 ] && [ "$found" -eq 0 ]
}

trap 'rm -rf "${TMPDIR:-/tmp}"/voxlight-fuzz-run-$$-* 2>/dev/null' EXIT
trap 'exit 130' INT TERM
jobs=${VOXLIGHT_FUZZ_JOBS:-1}
status=0
pids=()
for t in "${targets[@]}"; do
  mkdir -p "$build/findings"
  touch "$build/findings/$t.log.start"
  run_one "$t" "$@" &
  pids+=($!)
  if [ ${#pids[@]} -ge "$jobs" ]; then
    wait "${pids[0]}" || status=1
    pids=("${pids[@]:1}")
  fi
done
for p in "${pids[@]}"; do wait "$p" || status=1; done
exit $status
