#!/bin/sh
# The one test runner: compile-configuration checks, then every unit/property/driver test.
# Usage: tests/run.sh [name-filter]     SANITIZE=1 tests/run.sh  (ASan + UBSan build)
#        FULL=1 tests/run.sh (make test-all: the whole compile matrix, as CI runs it)
# Last line: N passed, N failed
cd "$(dirname "$0")/.." || exit 1
mkdir -p build
CC=${CC:-cc}
W="-Wall -Wextra -Werror -pedantic"
passed=0
failed=0
ok() { passed=$((passed + 1)); echo "ok   $1"; }
bad() { failed=$((failed + 1)); echo "FAIL $1"; }

# 1. the header in every configuration that matters, under every compiler found; two
# compiles at a time (the machine's two cores), results printed in order
cc_job() { # PREFIX COMMAND...: build PREFIX.bin, run it; the log and the status beside it
    pre=$1; shift
    if "$@" -o "$pre.bin" 2>"$pre.log" && "./$pre.bin" >>"$pre.log" 2>&1; then echo 0 >"$pre.rc"; else echo 1 >"$pre.rc"; fi
}
cc_n=0
cc_flush() {
    wait
    k=0
    while [ $k -lt $cc_n ]; do
        name=$(cat build/cc_$k.name)
        if [ "$(cat build/cc_$k.rc)" = 0 ]; then ok "$name"; else bad "$name"; sed 's/^/    /' build/cc_$k.log | head -20; fi
        k=$((k + 1))
    done
    cc_n=0
}
cc_launch() { # NAME COMMAND...
    echo "$1" >build/cc_$cc_n.name; shift
    cc_job build/cc_$cc_n "$@" &
    cc_n=$((cc_n + 1))
    if [ $cc_n -ge 2 ]; then cc_flush; fi
}
# FULL=1 (make test-all, what CI runs): every compiler x configuration x level, 52 builds. Else
# one build per distinct risk, 9: each compiler and language once, each configuration once, gcc
# at both levels, the host's vector units in float
if [ -z "$SANITIZE" ] && [ -z "$1" ] && [ -z "$FULL" ]; then
    first_cc() { for c in "$@"; do command -v "$c" >/dev/null 2>&1 && { echo "$c"; return; }; done; }
    ccc=$(first_cc gcc clang cc)
    cpp=$(first_cc g++ clang++)
    two="tests/compile_check.c tests/compile_check_tu2.c"
    # shellcheck disable=SC2086
    cc_launch "compile $ccc -std=c99 -O1 default" $ccc -std=c99 $W -O1 $two -lm
    # shellcheck disable=SC2086
    cc_launch "compile $ccc -std=c99 -O3 -DPN_REAL=float" $ccc -std=c99 $W -O3 -DPN_REAL=float $two -lm
    # shellcheck disable=SC2086
    cc_launch "compile $ccc -std=c99 -O3 -DPLASTINET_STATIC" $ccc -std=c99 $W -O3 -DPLASTINET_STATIC tests/compile_check.c -lm
    # shellcheck disable=SC2086
    cc_launch "compile $ccc -std=c99 -O1 -DPN_NO_STDIO" $ccc -std=c99 $W -O1 -DPN_NO_STDIO $two -lm
    # shellcheck disable=SC2086
    cc_launch "compile $ccc -std=c99 -O3 -DPN_NO_2D" $ccc -std=c99 $W -O3 -DPN_NO_2D $two -lm
    # shellcheck disable=SC2086
    cc_launch "compile $ccc -std=c99 -O1 -DPN_NO_3D" $ccc -std=c99 $W -O1 -DPN_NO_3D $two -lm
    if command -v clang >/dev/null 2>&1 && [ "$ccc" != clang ]; then
        # shellcheck disable=SC2086
        cc_launch "compile clang -std=c99 -O3 default" clang -std=c99 $W -O3 $two -lm
    fi
    if [ -n "$cpp" ]; then
        # shellcheck disable=SC2086
        cc_launch "compile $cpp c++11 -O1 default" $cpp -x c++ -std=c++11 $W -O1 $two -lm
    fi
    # shellcheck disable=SC2086
    cc_launch "compile $ccc -std=c99 -O3 -march=native -DPN_REAL=float" $ccc -std=c99 $W -O3 -march=native -DPN_REAL=float $two -lm
    cc_flush
fi
if [ -z "$SANITIZE" ] && [ -z "$1" ] && [ -n "$FULL" ]; then
    for cc in gcc clang g++ clang++; do
        command -v "$cc" >/dev/null 2>&1 || { echo "skip $cc (not installed)"; continue; }
        case $cc in *++) std="-x c++ -std=c++11";; *) std="-std=c99";; esac
        for cfg in "" "-DPLASTINET_STATIC" "-DPN_REAL=float" "-DPN_NO_STDIO" "-DPN_NO_2D" "-DPN_NO_3D"; do
            # gcc's flow-sensitive warnings (maybe-uninitialized) differ between levels
            for opt in -O1 -O3; do
                if [ "$cfg" = "-DPLASTINET_STATIC" ]; then srcs="tests/compile_check.c"; else srcs="tests/compile_check.c tests/compile_check_tu2.c"; fi
                # shellcheck disable=SC2086
                cc_launch "compile $cc ${std#-x c++ } $opt ${cfg:-default}" $cc $std $W $opt $cfg $srcs -lm
            done
        done
    done
    # what users build with: the host's vector units (gcc's flow-sensitive warnings differ again)
    for cc in gcc clang; do
        command -v "$cc" >/dev/null 2>&1 || continue
        for cfg in "" "-DPN_REAL=float"; do
            # shellcheck disable=SC2086
            cc_launch "compile $cc -std=c99 -O3 -march=native ${cfg:-default}" $cc -std=c99 $W -O3 -march=native $cfg \
                tests/compile_check.c tests/compile_check_tu2.c -lm
        done
    done
    cc_flush
fi

# 2. the test binaries: test_main (double, every test) and test_float (PN_REAL=float)
if [ -n "$SANITIZE" ]; then
    flags="-O1 -g -fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer"
    suffix=_san
else
    flags="-O2 -g"
    suffix=
fi
# tally NAME LOG STATUS: print LOG without its summary line, add that "N passed, N failed" to ours
tally() {
    grep -v '^[0-9]* passed, [0-9]* failed$' "$2"
    last=$(tail -n 1 "$2")
    p=$(echo "$last" | sed -n 's/^\([0-9]*\) passed, \([0-9]*\) failed$/\1/p')
    f=$(echo "$last" | sed -n 's/^\([0-9]*\) passed, \([0-9]*\) failed$/\2/p')
    if [ -z "$p" ]; then
        bad "$1 crashed or printed no summary (exit $3)"
    else
        passed=$((passed + p)); failed=$((failed + f))
        if [ "$3" -ne 0 ] && [ "$f" -eq 0 ]; then bad "$1 exit status $3"; fi
    fi
}
# run_bin NAME SOURCE EXTRA_FLAGS [filter]: build, run, add its "N passed, N failed" to ours
run_bin() {
    bin=build/$1$suffix
    # shellcheck disable=SC2086
    if ! $CC -std=c99 $W $flags $3 "$2" -lm -o "$bin"; then
        bad "build $bin"
        return
    fi
    shift 3
    ./"$bin" "$@" >"$bin.log" 2>&1
    tally "$bin" "$bin.log" $?
}
# run_bin_bg NAME SOURCE EXTRA_FLAGS [filter]: the same in the background (the other core);
# bg_tally NAME collects it
run_bin_bg() {
    bin=build/$1$suffix
    # shellcheck disable=SC2086
    ( if $CC -std=c99 $W $flags $3 "$2" -lm -o "$bin" 2>"$bin.build"; then
          shift 3
          ./"$bin" "$@" >"$bin.log" 2>&1
          echo $? >"$bin.rc"
      else
          echo build >"$bin.rc"
      fi ) &
    bg_pid=$!
}
bg_tally() {
    bin=build/$1$suffix
    wait "$bg_pid"
    if [ "$(cat "$bin.rc")" = build ]; then bad "build $bin"; sed 's/^/    /' "$bin.build" | head -20; return; fi
    tally "$bin" "$bin.log" "$(cat "$bin.rc")"
}
# the shipped models (models/pn_models.h, written by gen/export.py) are tested when present
models=
[ -f models/pn_models.h ] && models=-DPN_TEST_HAVE_MODELS
[ -f models/pn_rom_models.h ] && models="$models -DPN_TEST_HAVE_ROM_MODELS"
# test_main with OpenMP: the *_threads_identical tests check that 1 and 2 threads give the same bits
# test_main, the longest, on one core while the others build and run on the other
run_bin_bg test_main tests/test_main.c "$models -fopenmp" "$@"
run_bin test_float tests/test_float.c "-DPN_REAL=float" "$@"
# the float lanes of PlasticityNet in their other spellings: 8-lane vectors (AVX and up, what
# -march=native gives on x86-64) and the plain-struct path of compilers without vector types
if [ -z "$1" ]; then
    run_bin test_lanes_native tests/test_main.c "$models -march=native" pnet_lanes
    run_bin test_lanes_portable tests/test_main.c "$models -DPN_NO_VECTOR_EXTENSIONS" pnet_lanes
fi
run_bin test_render tests/test_render.c "" "$@"
bg_tally test_main

# 3. C against torch (gen/crosscheck.py): the training targets and every shipped model. Runs
#    whenever torch is installed (Debian: apt-get install -y python3-torch); CI requires it.
PY=${PY:-/usr/bin/python3}
if [ -z "$SANITIZE" ] && [ -z "$1" ]; then
    if "$PY" -c "import torch" >/dev/null 2>&1; then
        "$PY" gen/crosscheck.py >build/crosscheck.log 2>&1
        tally crosscheck build/crosscheck.log $?
        # the reduced-order models (models/rom_*.h): torch references, then the C evaluation
        if [ -f models/pn_rom_models.h ]; then
            for h in models/rom_*.h; do
                n=$(basename "$h" .h); n=${n#rom_}
                "$PY" gen/rom_crosscheck.py "$n" --out "build/rom_${n}_ref.txt" >>build/rom_crosscheck.log 2>&1
            done
            if $CC -std=c99 $W -O2 tests/rom_crosscheck.c -lm -o build/rom_crosscheck 2>>build/rom_crosscheck.log; then
                ./build/rom_crosscheck build >build/rom_crosscheck.out 2>&1
                tally rom_crosscheck build/rom_crosscheck.out $?
            else
                bad "build rom_crosscheck"; sed 's/^/    /' build/rom_crosscheck.log | head -10
            fi
        fi
    elif [ "${CI:-}" = true ]; then
        bad "crosscheck: torch is not installed (CI needs it: apt-get install -y python3-torch)"
    else
        echo "skip crosscheck (torch not installed: apt-get install -y python3-torch)"
    fi
fi
# 4. every example builds with the Makefile's line (make examples), and every C block of
#    README.md builds and runs (tests/readme_snippets.sh)
if [ -z "$SANITIZE" ] && [ -z "$1" ]; then
    if make -s examples >build/examples.log 2>&1; then ok "examples build (make examples)"
    else bad "examples build (make examples)"; sed 's/^/    /' build/examples.log | head -20; fi
fi
# 4b. the front door (issue 42), a few seconds in all: the demo at its defaults against the
#     explicit reference it runs itself (runout and height within 10%); explicit runs at their
#     stable step by default; every example's --help exits 0 and lists each flag it takes,
#     once; game_loop creates its picture folder
if [ -z "$SANITIZE" ] && [ -z "$1" ] && [ -x build/sand_column ]; then
    json=$(OMP_NUM_THREADS=1 build/sand_column --quiet 2>build/demo_check.err)
    ro=$(echo "$json" | sed -n 's/.*"runout_ratio": \([^,}]*\).*/\1/p')
    hr=$(echo "$json" | sed -n 's/.*"height_ratio": \([^,}]*\).*/\1/p')
    if [ -n "$ro" ] && [ -n "$hr" ] && awk -v a="$ro" -v b="$hr" 'BEGIN { exit !(a >= 0.9 && a <= 1.1 && b >= 0.9 && b <= 1.1) }'; then
        ok "demo_sand_column_matches_reference: runout and height over the explicit reference's $ro, $hr"
    else
        bad "demo_sand_column_matches_reference: runout ratio '$ro', height ratio '$hr' (bar: 0.9 .. 1.1)"
        sed 's/^/    /' build/demo_check.err | tail -5
    fi
    for e in sand_column snowball; do
        if OMP_NUM_THREADS=1 build/$e --integrator explicit --frames 3 --quiet >build/example_explicit.log 2>&1; then
            ok "example_explicit_default_step: $e --integrator explicit"
        else
            bad "example_explicit_default_step: $e --integrator explicit"; sed 's/^/    /' build/example_explicit.log | tail -5
        fi
    done
    for e in material_point sand_column snowball materials game_loop metal_frame drop_on_sand; do
        if ! build/$e --help >build/example_help.txt 2>&1; then bad "example_help: $e --help exits $?"; continue; fi
        # a flag defined twice: on two lines of the help that begin with it
        dup=$(grep -E '^ *--' build/example_help.txt | while read -r line; do
            echo "$line" | grep -oE -- '--[A-Za-z0-9-]+' | sort -u; done | sort | uniq -d | tr '\n' ' ')
        # a flag the source takes that the help does not name
        case $e in sand_column|snowball) src="examples/$e.c examples/pn_example.h";; game_loop) src=examples/$e.cpp;; *) src=examples/$e.c;; esac
        # shellcheck disable=SC2086
        miss=$(grep -ohE '"--[A-Za-z0-9-]+"' $src | tr -d '"' | sort -u | while read -r f; do
            grep -qE -- "(^|[^A-Za-z0-9-])$f([^A-Za-z0-9-]|$)" build/example_help.txt || echo "$f"; done | tr '\n' ' ')
        if [ -z "$dup" ] && [ -z "$miss" ]; then ok "example_help: $e"
        else bad "example_help: $e lists twice: '$dup'; takes but does not list: '$miss'"; fi
    done
    rm -rf build/example_png_dir
    if build/game_loop --frames 1 --res 16 --png build/example_png_dir/sub >build/example_png.log 2>&1 &&
        [ -d build/example_png_dir/sub ]; then
        ok "example_game_loop_png_mkdir"
    else
        bad "example_game_loop_png_mkdir: build/example_png_dir/sub not created"; sed 's/^/    /' build/example_png.log | tail -5
    fi
fi
if [ -z "$SANITIZE" ] && [ -z "$1" ]; then
    sh tests/readme_snippets.sh >build/readme_snippets.log 2>&1
    tally readme_snippets build/readme_snippets.log $?
fi
# 4c. one version everywhere: each header's banner, PN_VERSION_MAJOR/_MINOR and CHANGELOG.md's newest entry
if [ -z "$SANITIZE" ] && [ -z "$1" ]; then
    v=$(sed -n 's/^#define PN_VERSION_MAJOR \([0-9]*\)$/\1/p' plastinet.h).$(sed -n 's/^#define PN_VERSION_MINOR \([0-9]*\)$/\1/p' plastinet.h)
    c=$(sed -n 's/^## \([0-9][0-9.]*\).*/\1/p' CHANGELOG.md | head -n 1)
    vok=1
    for h in plastinet.h plastinet_mpm.h plastinet_rom.h; do
        head -n 1 "$h" | grep -q " - v$v - " || { vok=0; echo "    $h: banner $(head -n 1 "$h" | cut -c1-40) is not v$v"; }
    done
    [ "$c" = "$v" ] || { vok=0; echo "    CHANGELOG.md's newest entry is $c, PN_VERSION is $v"; }
    if [ $vok = 1 ]; then ok "version $v: banners, PN_VERSION and CHANGELOG.md agree"; else bad "version: banners, PN_VERSION and CHANGELOG.md disagree"; fi
fi
# 5. the same bits from every compiler (tests/cross_compiler.sh: gcc, g++, clang at -O2 with
#    -ffp-contract=off, every integrator and energy); skipped with fewer than two compilers
if [ -z "$SANITIZE" ] && [ -z "$1" ]; then
    sh tests/cross_compiler.sh >build/cross_compiler.log 2>&1
    tally cross_compiler build/cross_compiler.log $?
fi
# 5b. explicit MPM in float against double (bench/bench_explicit.c, the 88-line MLS-MPM scene
#     with 3000 particles, 0.15 s through the impact): the elastic blocks' mean height agrees to
#     5e-4 (float resolves a height of 0.2 m to 1.5e-8 m, and a step moves a particle 1e-4 m or
#     less, so each step's displacement is rounded by up to ~1e-4 of itself; over 1500 steps of
#     slowly varying velocity those roundings add up to a few 1e-4: measured 7.7e-5, and 2.1e-4
#     with one more wall row held; double is not sensitive there: E x (1 + 1e-6) or FMA on/off
#     move it < 1e-5); for the snow, which fractures (chaotic), the float-double gap is printed
#     beside what a change of E by 1e-6 does in double (docs/results.md: float works at the
#     precision the scene allows)
if [ -z "$SANITIZE" ] && [ -z "$1" ]; then
    ok_build=1
    for r in float double; do
        f=""; [ $r = float ] && f="-DPN_REAL=float"
        # shellcheck disable=SC2086
        $CC -std=c99 $W -O2 $f bench/bench_explicit.c -lm -o build/float_check_$r 2>>build/float_check.log || ok_build=0
    done
    if [ $ok_build = 1 ]; then
        hy() { "$@" | sed -n 's/.*mean_y=\([^ ]*\).*/\1/p'; }
        jf=$(hy build/float_check_float --per-block 1000 --steps 1500 --jelly)
        jd=$(hy build/float_check_double --per-block 1000 --steps 1500 --jelly)
        sf=$(hy build/float_check_float --per-block 1000 --steps 1500)
        sd=$(hy build/float_check_double --per-block 1000 --steps 1500)
        sp=$(hy build/float_check_double --per-block 1000 --steps 1500 --perturb 1e-6)
        if awk -v a="$jf" -v b="$jd" 'BEGIN { d = a - b; if (d < 0) d = -d; exit !(b > 0 && d / b <= 5e-4) }'; then
            ok "explicit MPM float vs double, elastic: mean height $jf vs $jd"
        else
            bad "explicit MPM float vs double, elastic: mean height $jf vs $jd (bar 5e-4 relative)"
        fi
        echo "    snow (chaotic): float $sf, double $sd, double with E x (1 + 1e-6) $sp"
    else
        bad "explicit MPM float check: build failed"; sed 's/^/    /' build/float_check.log | head -10
    fi
fi
# 6. the browser demo (examples/web, WebAssembly) in headless Chromium: tests/web_test.py. Runs
#    whenever emscripten, chromium and chromedriver are installed (Debian: apt-get install -y
#    emscripten chromium chromium-driver); CI requires them.
if [ -z "$SANITIZE" ] && [ -z "$1" ]; then
    if command -v emcc >/dev/null 2>&1 && command -v chromium >/dev/null 2>&1 &&
        command -v chromedriver >/dev/null 2>&1; then
        if make -s web >build/web_build.log 2>&1; then
            /usr/bin/python3 tests/web_test.py >build/web_test.log 2>&1
            tally web_test build/web_test.log $?
        else
            bad "web: make web failed"; sed 's/^/    /' build/web_build.log | head -20
        fi
    elif [ "${CI:-}" = true ]; then
        bad "web: emscripten/chromium/chromedriver not installed (apt-get install -y emscripten chromium chromium-driver)"
    else
        echo "skip web demo test (emscripten, chromium or chromedriver not installed: apt-get install -y emscripten chromium chromium-driver)"
    fi
fi
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
