#!/usr/bin/env bash
# Builds the libFuzzer targets (build/fuzz: clang-14, ASan + UBSan) and runs each from its seed
# corpus (tests/fuzz/corpus/<target>); exits non-zero on the first crash, leak, sanitizer report,
# uncaught exception, input slower than 25 s or single allocation over 1 GiB (the inputs are small:
# a reader that allocates that much believed a size in a header). Each target's last libFuzzer line
# (inputs run, cov, ft) is printed.
#   tests/fuzz/run.sh                   every target for 30 s
#   tests/fuzz/run.sh --time S [T...]   targets T (default: all) for S seconds each (./test.sh: 20 s)
#   tests/fuzz/run.sh --runs N [T...]   targets T for N inputs each (docs/reports/robustness.md)
#   --junitxml FILE (before the targets) also writes one JUnit test case per target to FILE.
# Every run first replays the committed corpus (seeds and the inputs that once crashed a target).
# New corpus entries go to build/fuzz/corpus/<target> (kept between runs, not committed); inputs
# that fail go to build/fuzz/artifacts/<target>/.
set -uo pipefail
cd "$(dirname "$0")/../.."
ROOT=$(pwd)
TARGETS=(scene_json obj ply image heightfield)
LIMIT=(-max_total_time=30)
JUNIT=""
while [ $# -gt 0 ]; do
  case "$1" in
    --time) LIMIT=(-max_total_time="$2"); shift 2 ;;
    --runs) LIMIT=(-runs="$2"); shift 2 ;;
    --junitxml) JUNIT=$2; shift 2 ;;
    *) break ;;
  esac
done
[ $# -gt 0 ] && TARGETS=("$@")
CASES=""  # JUnit test cases, one per target
junit() {  # writes $JUNIT (if asked for) with the cases so far, or one failure for the whole suite
  [ -n "$JUNIT" ] || return 0
  printf '<?xml version="1.0" encoding="UTF-8"?>\n<testsuites><testsuite name="fuzz">%s</testsuite></testsuites>\n' "$1" >"$JUNIT"
}
fail_all() { junit "<testcase classname=\"fuzz\" name=\"build\"><failure message=\"$1\"/></testcase>"; echo "fuzz: $1"; exit 1; }

command -v clang++-14 >/dev/null || fail_all "clang++-14 is missing (apt-get install clang-14 libclang-rt-14-dev)"
cmake -S . -B build/fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++-14 \
      -DLIMN_FUZZ=ON -DLIMN_TESTS=OFF -DLIMN_PYTHON=OFF >build/fuzz-configure.log 2>&1 \
  || { cat build/fuzz-configure.log; fail_all "cmake failed (build/fuzz-configure.log)"; }
ninja -C build/fuzz "${TARGETS[@]/#/fuzz_}" >build/fuzz-build.log 2>&1 || { tail -40 build/fuzz-build.log; fail_all "build failed (build/fuzz-build.log)"; }

export LSAN_OPTIONS="suppressions=$ROOT/tests/fuzz/lsan.supp"
export UBSAN_OPTIONS="print_stacktrace=1"
status=0
for t in "${TARGETS[@]}"; do
  mkdir -p "build/fuzz/corpus/$t" "build/fuzz/artifacts/$t"
  log="build/fuzz/$t.log"
  start=$SECONDS
  "build/fuzz/fuzz_$t" "${LIMIT[@]}" -rss_limit_mb=4096 -malloc_limit_mb=1024 -timeout=25 -print_final_stats=1 \
      -artifact_prefix="build/fuzz/artifacts/$t/" "build/fuzz/corpus/$t" "tests/fuzz/corpus/$t" >"$log" 2>&1
  rc=$?
  runs=$(grep -E '^stat::number_of_executed_units' "$log" | awk '{print $2}')
  last=$(grep -E '^#[0-9]+' "$log" | tail -1)
  printf 'fuzz_%-12s %s inputs in %d s; %s\n' "$t" "${runs:-?}" $((SECONDS - start)) "${last:-no stats}"
  case_xml="<testcase classname=\"fuzz\" name=\"fuzz_$t\" time=\"$((SECONDS - start))\">"
  if [ $rc -ne 0 ]; then
    status=1
    grep -E 'ERROR|SUMMARY|invariant|uncaught|Test unit written' "$log" | head -20
    echo "fuzz_$t FAILED (exit $rc); full log: $log"
    case_xml+="<failure message=\"exit $rc, see $log\"/>"
  fi
  CASES+="$case_xml</testcase>"
done
junit "$CASES"
exit $status
