#!/usr/bin/env bash
# firmware_ref/fuzz/run.sh SECONDS [OUT]: build the libFuzzer harnesses (clang-14, ASan + UBSan) in
# FUZZ_BUILD and run each for SECONDS, FUZZ_JOBS (default 2) at a time, then print one line
# per harness: executions, exec/s, libFuzzer's final cov: and ft:, findings. Exit 0 when nothing was found,
# 1 when a harness found a crash, a leak or a timeout (its input is OUT/findings/<harness>-*), 2 when the
# build failed.
#   OUT          working corpora, logs and findings (default firmware_ref/build-fuzz/run)
#   FUZZ_SEEDS   a folder of extra seeds, one subfolder per harness (tests/test_fuzz.py makes them)
#   FWREF_FUZZ_WEIGHTS  the weights.bin the stream and windows harnesses run (default: the committed seed)
#   FUZZ_BUILD   the build folder (default firmware_ref/build-fuzz)
# `make fuzz` runs it with FUZZ_SECONDS (default 600 per harness); `make test` for a few seconds each.
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
seconds=${1:?usage: run.sh SECONDS [OUT]}
build=${FUZZ_BUILD:-$here/../build-fuzz}
out=${2:-$build/run}
jobs=${FUZZ_JOBS:-2}
harnesses=(fuzz_weights fuzz_reference fuzz_windows fuzz_stream)
declare -A max_len=([fuzz_weights]=65536 [fuzz_reference]=131072 [fuzz_windows]=16384 [fuzz_stream]=32768)

rm -rf "$out/findings"
mkdir -p "$build" "$out/findings"
{
  flock 9  # one build at a time in the folder (two test sessions, or a test and `make fuzz`)
  if ! { cmake -S "$here" -B "$build" -DCMAKE_CXX_COMPILER=clang++-14 && cmake --build "$build" -j 2; } \
      >"$build/build.log" 2>&1; then
    echo "run.sh: building the fuzz harnesses failed; full log: $build/build.log" >&2
    grep -m1 -i "error" "$build/build.log" >&2
    exit 2
  fi
} 9>"$build/.lock"

run_one() {
  local name=$1 seeds=()
  mkdir -p "$out/corpus/$name"
  [ -d "$here/corpus/$name" ] && seeds+=("$here/corpus/$name")
  [ -n "${FUZZ_SEEDS:-}" ] && [ -d "$FUZZ_SEEDS/$name" ] && seeds+=("$FUZZ_SEEDS/$name")
  "$build/$name" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -max_len="${max_len[$name]}" \
    -print_final_stats=1 -artifact_prefix="$out/findings/$name-" "$out/corpus/$name" "${seeds[@]}" \
    >"$out/$name.log" 2>&1
  echo $? >"$out/$name.rc"
}

for name in "${harnesses[@]}"; do
  while [ "$(jobs -rp | wc -l)" -ge "$jobs" ]; do wait -n; done
  run_one "$name" &
done
wait

status=0
for name in "${harnesses[@]}"; do
  log=$out/$name.log
  rc=$(cat "$out/$name.rc" 2>/dev/null || echo 99)
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  speed=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
  ft=$(grep -o 'ft: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
  found=$(find "$out/findings" -name "$name-*" | wc -l)
  echo "$name: runs=${runs:-0} exec_per_s=${speed:-0} cov=${cov:-0} ft=${ft:-0} findings=$found rc=$rc seconds=$seconds"
  if [ "$rc" != 0 ] || [ "$found" != 0 ]; then
    status=1
    grep -m3 -E "ERROR|runtime error|invariant|ALARM|leak" "$log" | sed "s/^/  $name: /"
  fi
done
exit $status
