#!/usr/bin/env bash
# Runs the libFuzzer harnesses built in BUILD_DIR (make fuzz-build), each for FUZZ_SECONDS
# (default 60; issue 21's acceptance run is 300 per harness), with a 1 GB RSS / malloc limit,
# FUZZ_PARALLEL at a time (default 1), and prints harness / runs / crashes. Exit status 1 when any harness found
# something; its reproducer is in BUILD_DIR/fuzz-artifacts/HARNESS/ and its log next to it.
#   usage: fuzz/run.sh BUILD_DIR [HARNESS...]      (default: every harness)
# The corpus grown by earlier runs is kept in BUILD_DIR/fuzz-corpus/HARNESS; the seeds are
# rewritten each time by fuzz_make_seeds (io writers) plus the YAML files in config/.
set -u
build=${1:?usage: fuzz/run.sh BUILD_DIR [HARNESS...]}
shift
harnesses=("$@")
[ ${#harnesses[@]} -eq 0 ] && harnesses=(pcd ply g2o poses kitti_bin scd config blob json)
seconds=${FUZZ_SECONDS:-60}
root=$(cd "$(dirname "$0")/.." && pwd)
build=$(cd "$build" && pwd)

seeds=$build/fuzz-seeds
rm -rf "$seeds"
"$build/fuzz/fuzz_make_seeds" "$seeds" || { echo "fuzz_make_seeds failed" >&2; exit 2; }
cp "$root"/config/*.yaml "$seeds/config/"

export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:allocator_may_return_null=0}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}

# The readers' tests, instrumented (the crashes found so far are cases of test_io_bad_input.cpp).
if [ -x "$build/fuzz/fuzz_io_tests" ]; then
  "$build/fuzz/fuzz_io_tests" --gtest_brief=1 > "$build/fuzz-io-tests.log" 2>&1 ||
    { tail -30 "$build/fuzz-io-tests.log"; echo "fuzz_io_tests failed" >&2; exit 1; }
  echo "== fuzz_io_tests passed (tests/test_io_bad_input.cpp, tests/test_io_formats.cpp under ASan + UBSan)"
fi
# One harness: run it for $seconds, then write its table row to $art.row (rc in $art.rc).
fuzz_one() {
  local h=$1 bin=$build/fuzz/fuzz_$1 corpus=$build/fuzz-corpus/$1 art=$build/fuzz-artifacts/$1
  local log=$build/fuzz-artifacts/$1.log rc runs crashes what=""
  nice -n 10 "$bin" -max_total_time="$seconds" -rss_limit_mb=1024 -malloc_limit_mb=1024 -timeout=30 \
    -print_final_stats=1 -artifact_prefix="$art/" "$corpus" "$seeds/$h" > "$log" 2>&1
  rc=$?
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | tail -1 | grep -o '[0-9]*$')
  [ -z "$runs" ] && runs=$(grep -o '^#[0-9]*' "$log" | tail -1 | tr -d '#')
  crashes=$(find "$art" -maxdepth 1 -type f \( -name 'crash-*' -o -name 'leak-*' -o -name 'oom-*' \
            -o -name 'timeout-*' \) | wc -l)
  [ "$rc" -ne 0 ] && [ "$crashes" -eq 0 ] && crashes=1
  if [ "$crashes" -ne 0 ]; then
    what=$(grep -m1 -E 'ERROR: (AddressSanitizer|LeakSanitizer|libFuzzer)|runtime error|terminate called|==ERROR' "$log" | cut -c1-100)
  fi
  printf '%-10s %12s %8s  %s' "$h" "${runs:-?}" "$crashes" "$what" > "$art.row"
  echo "$crashes" > "$art.rc"
}

# FUZZ_PARALLEL harnesses at a time (default 1; one core each).
parallel=${FUZZ_PARALLEL:-1}
for h in "${harnesses[@]}"; do
  [ -x "$build/fuzz/fuzz_$h" ] || { echo "no harness $build/fuzz/fuzz_$h (make fuzz-build)" >&2; exit 2; }
done
for h in "${harnesses[@]}"; do
  art=$build/fuzz-artifacts/$h
  mkdir -p "$build/fuzz-corpus/$h" "$art"
  rm -f "$art"/* "$art.row" "$art.rc"
  while [ "$(jobs -rp | wc -l)" -ge "$parallel" ]; do wait -n; done
  echo "== fuzz_$h for ${seconds}s (log: $art.log)"
  fuzz_one "$h" &
done
wait
rows=()
status=0
for h in "${harnesses[@]}"; do
  art=$build/fuzz-artifacts/$h
  rows+=("$(cat "$art.row")")
  [ "$(cat "$art.rc")" -ne 0 ] && status=1
done
echo
printf '%-10s %12s %8s  %s\n' harness runs crashes "first report"
printf '%s\n' "${rows[@]}"
exit $status
