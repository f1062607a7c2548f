#!/usr/bin/env bash
# Runs every test of limn and ends with one summary line "N passed, N failed":
#   C++ core (doctest), Python package (pytest), Blender add-on in Debian's Blender 3.4 and in the
#   bpy module (Blender 4.5 LTS from PyPI), and the libFuzzer targets briefly (tests/fuzz/run.sh;
#   FUZZ_SECONDS=S per target, default 20). Installs and builds what is missing first.
#   ./test.sh --sanitize   also builds the core, its tests and the Python module under AddressSanitizer
#                          and UndefinedBehaviorSanitizer (build/asan) and runs the C++ suite and a
#                          Python subset with them (docs/testing.md, "Sanitizers"); CI runs this.
set -uo pipefail
cd "$(dirname "$0")"
SANITIZE=0
[ "${1:-}" = "--sanitize" ] && SANITIZE=1
./bootstrap.sh --bpy || { echo "bootstrap failed"; exit 1; }

RESULTS=build/test-results
rm -rf "$RESULTS" && mkdir -p "$RESULTS"
PY=.venv/bin/python
status=0
suite() {  # suite NAME REPORT COMMAND...: REPORT is the JUnit file the command writes in $RESULTS
  local name=$1 report=$2; shift 2
  echo "$report" >> "$RESULTS/expected.txt"
  printf '\n\033[1m== %s ==\033[0m\n' "$name"
  local t0=$SECONDS
  "$@" || status=1
  echo "($name: $((SECONDS - t0)) s)"
}

suite "C++ core (doctest)" cpp.xml build/cpp/limn_tests --reporters=junit --out="$RESULTS/cpp.xml" --no-intro
suite "Python package (pytest)" python.xml "$PY" -m pytest -q tests/python --junitxml="$RESULTS/python.xml"
# Each libFuzzer target replays its committed corpus, then fuzzes for FUZZ_SECONDS (default 20).
FUZZ_SECONDS=${FUZZ_SECONDS:-20}
suite "Fuzz targets (libFuzzer, ${FUZZ_SECONDS} s each)" fuzz.xml tests/fuzz/run.sh --time "$FUZZ_SECONDS" --junitxml "$RESULTS/fuzz.xml"
suite "Blender 3.4 add-on (Debian blender)" blender-3.4.xml blender -b --factory-startup -noaudio --python-exit-code 1 \
      --python tests/blender/run.py -- --junitxml="$RESULTS/blender-3.4.xml"
suite "Blender 4.5 LTS add-on (bpy module)" blender-bpy.xml "$PY" tests/blender/run.py --junitxml="$RESULTS/blender-bpy.xml"
suite "Blender 3.4 in a window (Xvfb)" blender-window.xml "$PY" -m pytest -q -p no:cacheprovider tests/blender/window \
      --junitxml="$RESULTS/blender-window.xml"

if [ "$SANITIZE" = 1 ]; then
  # The core, its doctests and the Python module built with ASan + UBSan (any report aborts the
  # test that triggers it), then the C++ suite and a Python subset run against them. The Python
  # interpreter is not instrumented: libasan is preloaded, and leak detection is off for Python
  # (the interpreter's own allocations at exit), on for the C++ suite.
  printf '\n\033[1m== building under ASan + UBSan (build/asan) ==\033[0m\n'
  SAN="-fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer"
  cmake -S . -B build/asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DLIMN_TESTS=ON -DLIMN_PYTHON=ON \
        -DCMAKE_CXX_FLAGS="$SAN" -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" \
        -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=address,undefined" -DPython_EXECUTABLE="$PWD/$PY" \
        -Dpybind11_DIR="$("$PY" -m pybind11 --cmakedir)" > build/asan-configure.log 2>&1 \
    && ninja -C build/asan limn_tests _core > build/asan-build.log 2>&1 \
    || { tail -40 build/asan-configure.log build/asan-build.log; status=1; }
  rm -rf build/asan/python && mkdir -p build/asan/python
  cp -r bindings/limn build/asan/python/ && cp build/asan/_core*.so build/asan/python/limn/ 2>/dev/null
  mkdir -p build/asan/python/limn/examples/scenes && cp -r scenes/shadow_wall build/asan/python/limn/examples/scenes/
  export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
  suite "C++ core under ASan + UBSan" cpp-asan.xml env ASAN_OPTIONS=detect_leaks=1 \
        build/asan/limn_tests --reporters=junit --out="$RESULTS/cpp-asan.xml" --no-intro
  # The subset: API, loading, bad and hostile input, known answers, extreme cases, the non-finite
  # policy and the interior and boundary derivative tests that run in seconds (docs/testing.md).
  suite "Python subset under ASan + UBSan" python-asan.xml \
        env LD_PRELOAD="$(gcc -print-file-name=libasan.so):$(gcc -print-file-name=libubsan.so)" ASAN_OPTIONS=detect_leaks=0 \
        PYTHONPATH="$PWD/build/asan/python" "$PY" -m pytest -q -p no:cacheprovider \
        tests/python/test_api.py tests/python/test_bad_input.py tests/python/test_known_answers.py \
        tests/python/test_extreme.py tests/python/test_nonfinite_policy.py tests/python/test_architecture.py \
        tests/python/test_primary_visibility.py --junitxml="$RESULTS/python-asan.xml"
fi

printf '\n'
"$PY" tests/summarize.py "$RESULTS" || status=1
exit $status
