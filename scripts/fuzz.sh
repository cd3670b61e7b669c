#!/usr/bin/env bash
# Fuzzes one reader with libFuzzer: scripts/fuzz.sh TARGET SECONDS [RUNS]
#   TARGET: scenario | gmsh | tetgen | csv | capture | fields
#   stops after SECONDS, or after RUNS executions when given (e.g. 1000000)
# Builds build-fuzz with clang (installed here when missing), seeds the corpus from
# yaml/examples and tests/data, and runs for SECONDS. Inputs that crash, leak past
# the limits or throw anything but kelvin's own error land in fuzz/crashers/TARGET/;
# commit them as regression inputs. Prints libFuzzer's final statistics.
set -euo pipefail
cd "$(dirname "$0")/.."
target=${1:?target: scenario gmsh tetgen csv capture fields}
seconds=${2:-60}
runs=${3:--1}
if ! command -v clang++ >/dev/null; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get install -y -qq --no-install-recommends clang >/dev/null
fi
CC=clang CXX=clang++ cmake -S . -B build-fuzz -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DKELVIN_FUZZ=ON -DBUILD_TESTING=OFF -DKELVIN_BUILD_BENCH=OFF >/dev/null
cmake --build build-fuzz -j2 --target "fuzz_${target}" >/dev/null
corpus=build-fuzz/corpus/${target}
crashers=fuzz/crashers/${target}
mkdir -p "$corpus" "$crashers"
seed() { for f in "$@"; do [ -f "$f" ] && cp "$f" "$corpus/" 2>/dev/null || true; done; }
case $target in
  scenario) seed yaml/examples/*.yaml yaml/examples/*/*.yaml tests/data/cli/*.yaml tests/data/scenarios/*.yaml ;;
  gmsh) seed tests/data/meshes/*.msh ;;
  tetgen) for n in tests/data/meshes/*.node; do
            { cat "$n"; echo "#ele"; cat "${n%.node}.ele" 2>/dev/null || true; } > "$corpus/$(basename "$n")"
          done ;;
  csv) for f in tests/data/csv/*.csv; do
         for k in 0 1 2; do { printf "\\x3$k"; cat "$f"; } > "$corpus/$k-$(basename "$f")"; done
       done ;;
  capture) for f in tests/data/capture/*; do { printf "1"; cat "$f"; } > "$corpus/$(basename "$f")"; done
           for f in tests/data/capture/*.c3d; do [ -f "$f" ] && { printf "0"; cat "$f"; } > "$corpus/$(basename "$f")"; done ;;
  fields) seed tests/data/scenarios/*.csv yaml/examples/*/*fields*.csv ;;
  *) echo "unknown target $target" >&2; exit 1 ;;
esac
# A hang is an input still running after a minute: a valid scenario may generate a
# mesh of up to 2 M tetrahedra, which takes seconds (several times that under ASan),
# so only units slower than that minute are reported as slow (and written).
ASAN_OPTIONS=detect_leaks=0 UBSAN_OPTIONS=halt_on_error=1 \
  "build-fuzz/bin/fuzz_${target}" "$corpus" -max_total_time="$seconds" -runs="$runs" -timeout=60 \
  -report_slow_units=60 -rss_limit_mb=2048 -max_len=65536 -artifact_prefix="$crashers/" -print_final_stats=1 2>&1 |
  grep -E "^(stat::|#[0-9]+ *DONE|==[0-9]+==|SUMMARY|artifact_prefix|Test unit written)" || true
