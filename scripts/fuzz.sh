#!/usr/bin/env bash
# Runs crumple's libFuzzer targets (docs/fuzzing.md). Needs the fuzz preset built:
#   cmake --preset fuzz && cmake --build --preset fuzz
#   bash scripts/fuzz.sh TARGET SECONDS [WORKDIR]   one campaign: TARGET is obj, ply, off or x3d;
#                                                   the corpus grows in WORKDIR/corpus (default
#                                                   fuzz-out/TARGET), findings land in WORKDIR
#   bash scripts/fuzz.sh ci SECONDS                 every target for SECONDS over a temporary
#                                                   copy of its seed corpus, one per core at a
#                                                   time; one summary line per target; exits 1
#                                                   on any finding
# The repository's seed corpus (tests/fuzz/corpus/TARGET) is read, never written.
set -euo pipefail
cd "$(dirname "$0")/.."

BUILD=${FUZZ_BUILD:-build/fuzz}
# Inputs up to 1 MB; a finding is also an input that runs over 60 s or uses over 2 GB.
FLAGS=(-max_len=1048576 -timeout=60 -rss_limit_mb=2048 -print_final_stats=1)
export ASAN_OPTIONS=${ASAN_OPTIONS:-abort_on_error=1:detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}

# Stops (exit 2, one line naming them) unless every given target's binary is built: a missing
# binary is a broken setup, not a finding, and nothing is run.
need_binaries() {  # need_binaries TARGET...
  local missing=()
  for target in "$@"; do
    [ -x "$BUILD/tests/fuzz/fuzz_$target" ] || missing+=("$BUILD/tests/fuzz/fuzz_$target")
  done
  if ((${#missing[@]})); then
    echo "fuzz.sh: not built: ${missing[*]}; build them first: cmake --preset fuzz && cmake --build --preset fuzz (or set FUZZ_BUILD)" >&2
    exit 2
  fi
}

# The executions that libFuzzer's final statistics in LOG report, or ? when it has none.
executions() {  # executions LOG
  local n
  n=$( { sed -n 's/^stat::number_of_executed_units: *//p' "$1" 2>/dev/null || true; } | tail -1)
  echo "${n:-?}"
}

run_target() {  # run_target TARGET SECONDS WORKDIR LOG
  local target=$1 seconds=$2 work=$3 log=$4
  local bin="$BUILD/tests/fuzz/fuzz_$target"
  mkdir -p "$work/corpus"
  "$bin" "${FLAGS[@]}" -max_total_time="$seconds" -artifact_prefix="$work/" \
    "$work/corpus" "tests/fuzz/corpus/$target" >"$log" 2>&1
}

case "${1:-}" in
  ci)
    seconds=${2:?usage: scripts/fuzz.sh ci SECONDS}
    need_binaries obj ply off x3d
    tmp=$(mktemp -d)
    trap 'rm -rf "$tmp"' EXIT
    # One target per core at a time (FUZZ_JOBS, default nproc): each fuzzer is one process on
    # one core, so running them side by side gives each the executions it would get alone.
    parallel=${FUZZ_JOBS:-$(nproc)}
    for target in obj ply off x3d; do
      while (($(jobs -rp | wc -l) >= parallel)); do wait -n || true; done
      { run_target "$target" "$seconds" "$tmp/$target" "$tmp/$target.log" && echo ok || echo FINDING; } \
        >"$tmp/$target.result" &
    done
    wait
    status=0
    for target in obj ply off x3d; do
      result=$(cat "$tmp/$target.result")
      echo "fuzz_$target: $(executions "$tmp/$target.log") executions in ${seconds} s: $result"
      if [ "$result" != ok ]; then
        status=1
        tail -n 60 "$tmp/$target.log" >&2
        ls "$tmp/$target"/crash-* "$tmp/$target"/timeout-* "$tmp/$target"/oom-* 2>/dev/null >&2 || true
      fi
    done
    exit $status
    ;;
  obj|ply|off|x3d)
    target=$1
    seconds=${2:?usage: scripts/fuzz.sh TARGET SECONDS [WORKDIR]}
    work=${3:-fuzz-out/$target}
    need_binaries "$target"
    mkdir -p "$work"
    echo "== fuzz_$target for $seconds s; log $work/fuzz.log, findings $work/{crash,timeout,oom}-*"
    if run_target "$target" "$seconds" "$work" "$work/fuzz.log"; then result=ok; else result=FINDING; fi
    echo "fuzz_$target: $(executions "$work/fuzz.log") executions in $seconds s: $result"
    [ "$result" = ok ] || { tail -n 60 "$work/fuzz.log" >&2; exit 1; }
    ;;
  *)
    echo "usage: bash scripts/fuzz.sh obj|ply|off|x3d SECONDS [WORKDIR] | ci SECONDS" >&2
    exit 2
    ;;
esac
