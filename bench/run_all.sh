#!/usr/bin/env bash
# Runs every Google Benchmark program in the build directory and prints the figures.
set -euo pipefail
BUILD_DIR="${1:-build}"
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
for b in "$BUILD_DIR"/bench/bench_*; do
  [ -x "$b" ] || continue
  echo "== $(basename "$b")"
  "$b" --benchmark_counters_tabular=true
done
