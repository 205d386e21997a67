#!/bin/sh
# The one test runner. Last line: N passed, N failed.
#   make test           tests/run.sh             the loop of minutes: about 3.5 min on 2 idle cores
#   make test-all       FULL=1 tests/run.sh      what CI runs: make test, the whole compile matrix
#                                                and every case of the test binaries' sweeps
#   make test-sanitize  SANITIZE=1 tests/run.sh  the test binaries alone, under AddressSanitizer
#                                                and UBSan (CI), the sweeps' representative subsets
#   tests/run.sh NAME                            the test binaries' tests whose name contains NAME
#   TEST_JOBS=N                                  jobs at a time (default 2: the two cores)
#   build/run/times                              each job's end, start and name (CI prints the
#                                                slowest jobs before the last line)
#
# What runs where (CI runs test-all and test-sanitize, so every check runs there at least once):
#   check                                          make test    test-all     test-sanitize
#   the headers' compile matrix (tests/compile_      4 builds     42 builds    -
#     check.c: 4 compilers x 6 configurations, gcc
#     and g++ at 2 levels, + the host's vector
#     units + PN_NO_FEM in C and C++)
#   test_main, test_float, test_render             quick        every case   quick, sanitized
#   (PN_TEST_FULL=1: every case of the sweeps;
#    else each sweep's subset, named in the test)
#   float lanes: -march=native, no vector types    yes          yes          -
#   torch cross-checks (gen/crosscheck.py, ROM)    yes          yes          -
#   examples build (make test: the front door's     yes          yes          -
#     two with make, the rest at -O0 -Werror;
#     test-all: all with make), front door,
#     README blocks
#   same bits from every compiler, float vs double yes          yes          -
#   one version everywhere                         yes          yes          -
#   the browser demo (emscripten + chromium)       if installed required     -
# The other compile risks are covered by builds made anyway: test_main is gcc C99 -O2 with
# -Werror, test_float the same in float, tests/cross_compiler.sh builds with gcc, clang and g++
# (C++11) at -O2 with -Werror.
#
# How: one queue of jobs run TEST_JOBS at a time (xargs -P), the longest first: phase 1 builds
# (and runs what needs nothing else), phase 2 runs test_main's tests, one process each, and what
# needs the examples. Phase 2's jobs join the queue as soon as test_main is built (its list comes
# from the binary), so they fill the slots phase 1's last jobs leave idle. Each job writes build/run/JOB.log ending in its own
# "N passed, N failed"; the logs are printed after, in a fixed order (the same output as one
# process, whatever the timing).
cd "$(dirname "$0")/.." || exit 1
R=build/run
mkdir -p "$R/t"
CC=${CC:-cc}
PY=${PY:-/usr/bin/python3}
W="-Wall -Wextra -Werror -pedantic"
if [ -n "$FULL" ]; then PN_TEST_FULL=1; export PN_TEST_FULL; fi
if [ -n "$SANITIZE" ]; then
    flags="-O1 -g -fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer"
    suffix=_san
else
    flags="-O2 -g"
    suffix=
fi
# the shipped models (models/pn_models.h, written by gen/export.py) are tested when present
models=
[ -f models/pn_models.h ] && models=-DPN_TEST_HAVE_MODELS
[ -f models/pn_rom_models.h ] && models="$models -DPN_TEST_HAVE_ROM_MODELS"
passed=0
failed=0
ok() { passed=$((passed + 1)); echo "ok   $1"; }
bad() { failed=$((failed + 1)); echo "FAIL $1"; }
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
summary() { echo "$passed passed, $failed failed"; }

# ---- the jobs (tests/run.sh --job JOB runs one; its output is its log) -------------------------

# the compile matrix: one line per build, "NAME|COMMAND" (COMMAND gets -o BINARY; the binary runs)
cc_list() {
    two="tests/compile_check.c tests/compile_check_tu2.c"
    if [ -z "$FULL" ]; then
        # one build per distinct risk not built anyway (see the top): each configuration once,
        # each level, C++, the host's vector units in float
        first_cc() { for c in "$@"; do command -v "$c" >/dev/null 2>&1 && { echo "$c"; return; }; done; }
        ccc=$(first_cc gcc clang cc)
        clg=$(first_cc clang gcc cc)
        cpp=$(first_cc g++ clang++)
        # (independent configurations share a build: each macro is compiled at least once; -O3
        # is the float build's, clang's warnings come from its front end at any level)
        echo "compile $ccc -std=c99 -O1 -DPN_NO_STDIO -DPLASTINET_STATIC|$ccc -std=c99 $W -O1 -DPN_NO_STDIO -DPLASTINET_STATIC tests/compile_check.c -lm"
        echo "compile $clg -std=c99 -O1 -DPN_NO_2D -DPN_NO_FEM|$clg -std=c99 $W -O1 -DPN_NO_2D -DPN_NO_FEM $two -lm"
        [ -n "$cpp" ] && echo "compile $cpp c++11 -O1 -DPN_NO_3D|$cpp -x c++ -std=c++11 $W -O1 -DPN_NO_3D $two -lm"
        echo "compile $ccc -std=c99 -O3 -march=native -DPN_REAL=float|$ccc -std=c99 $W -O3 -march=native -DPN_REAL=float $two -lm"
        return
    fi
    for cc in gcc clang g++ clang++; do
        command -v "$cc" >/dev/null 2>&1 || continue
        case $cc in *++) std="-x c++ -std=c++11";; *) std="-std=c99";; esac
        for cfg in "" "-DPLASTINET_STATIC" "-DPN_REAL=float" "-DPN_NO_STDIO" "-DPN_NO_2D" "-DPN_NO_3D"; do
            # gcc's flow-sensitive warnings (maybe-uninitialized) differ between levels; clang's
            # come from its front end, the same at any level: one level for clang
            case $cc in clang*) levels="-O2";; *) levels="-O1 -O3";; esac
            for opt in $levels; do
                if [ "$cfg" = "-DPLASTINET_STATIC" ]; then srcs="tests/compile_check.c"; else srcs="$two"; fi
                echo "compile $cc ${std#-x c++ } $opt ${cfg:-default}|$cc $std $W $opt $cfg $srcs -lm"
            done
        done
    done
    # a game's particles-only build: FEM and coupling left out (C and C++)
    for cc in gcc g++; do
        command -v "$cc" >/dev/null 2>&1 || continue
        case $cc in *++) std="-x c++ -std=c++11";; *) std="-std=c99";; esac
        echo "compile $cc ${std#-x c++ } -O2 -DPN_NO_FEM|$cc $std $W -O2 -DPN_NO_FEM $two -lm"
    done
    # what users build with: the host's vector units (gcc's flow-sensitive warnings differ again)
    for cc in gcc clang; do
        command -v "$cc" >/dev/null 2>&1 || continue
        for cfg in "" "-DPN_REAL=float"; do
            echo "compile $cc -std=c99 -O3 -march=native ${cfg:-default}|$cc -std=c99 $W -O3 -march=native $cfg $two -lm"
        done
    done
}
job_cc() { # K: line K of the compile matrix
    line=$(sed -n "${1}p" "$R/cc.list")
    name=${line%%|*}
    # shellcheck disable=SC2086
    if ${line#*|} -o "$R/cc_$1.bin" >"$R/cc_$1.out" 2>&1 && "./$R/cc_$1.bin" >>"$R/cc_$1.out" 2>&1; then ok "$name"
    else bad "$name"; sed 's/^/    /' "$R/cc_$1.out" | head -20; fi
    rm -f "$R/cc_$1.bin"
}
# build NAME SOURCE EXTRA_FLAGS: build/NAME (with _san under SANITIZE)
build() {
    # shellcheck disable=SC2086
    if $CC -std=c99 $W $flags $3 "$2" -lm -o "build/$1$suffix" 2>"$R/$1.build"; then ok "build build/$1$suffix"
    else bad "build build/$1$suffix"; sed 's/^/    /' "$R/$1.build" | head -20; fi
}
# run_bin NAME [filter]: run build/NAME, its lines and its count into ours
run_bin() {
    bin=build/$1$suffix
    shift
    if [ ! -x "$bin" ]; then bad "$bin was not built"; return; fi
    ./"$bin" "$@" >"$R/out.$$" 2>&1
    tally "$bin" "$R/out.$$" $?
    rm -f "$R/out.$$"
}
# test_main (double, every test) with OpenMP: the *_threads_identical tests compare 1 and 2 threads
job_build_main() { build test_main tests/test_main.c "$models -fopenmp"; }
job_float() { build test_float tests/test_float.c "-DPN_REAL=float" && run_bin test_float ${FILTER:+"$FILTER"}; }
job_render() { build test_render tests/test_render.c "" && run_bin test_render ${FILTER:+"$FILTER"}; }
# the float lanes of PlasticityNet in their other spellings (tests/test_lanes.c): 8-lane vectors
# (AVX and up, what -march=native gives on x86-64) and the plain-struct path of compilers without
# vector types
job_lanes_native() { build test_lanes_native tests/test_lanes.c "$models -march=native" && run_bin test_lanes_native; }
job_lanes_portable() {
    build test_lanes_portable tests/test_lanes.c "$models -DPN_NO_VECTOR_EXTENSIONS" && run_bin test_lanes_portable
}
job_t() { # NAME: one test of test_main, in its own process, on one thread: jobs run TEST_JOBS at a
    # time, and two OpenMP teams spinning on two cores took multigrid_default_3d from 5 s to 140
    # (the tests of thread counts set their own)
    OMP_NUM_THREADS=1 OMP_WAIT_POLICY=passive ./build/test_main$suffix "=$1" >"$R/t/$1.out" 2>&1
    tally "$1" "$R/t/$1.out" $?
    rm -f "$R/t/$1.out"
}
# C against torch (gen/crosscheck.py): the training targets and every shipped model. Runs
# whenever torch is installed (Debian: apt-get install -y python3-torch); CI requires it.
job_crosscheck() {
    if "$PY" -c "import torch" >/dev/null 2>&1; then
        "$PY" gen/crosscheck.py >build/crosscheck.log 2>&1
        tally crosscheck build/crosscheck.log $?
        # the reduced-order models (models/rom_*.h): torch references, then the C evaluation
        if [ -f models/pn_rom_models.h ]; then
            : >build/rom_crosscheck.log
            for h in models/rom_*.h; do
                n=$(basename "$h" .h); n=${n#rom_}
                "$PY" gen/rom_crosscheck.py "$n" --out "build/rom_${n}_ref.txt" >>build/rom_crosscheck.log 2>&1
            done
            # shellcheck disable=SC2086
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
}
# every example builds with the Makefile's line (make examples: one job per example)
EXAMPLES="sand_column snowball materials game_loop metal_frame drop_on_sand rom_poke rom_tower material_point"
# make test builds the examples the front door runs (sand_column, snowball) as the Makefile does,
# and the others, which it only asks for --help, at -O0 with -Werror into build/run/ex (a
# fraction of the compile time; build/ keeps no slower binary); make test-all (FULL) builds
# every one with make.
job_ex() {
    case " sand_column snowball " in *" $1 "*) full=1;; *) full=$FULL;; esac
    if [ -n "$full" ]; then
        if make -s "build/$1" >"$R/ex_$1.out" 2>&1; then ok "example builds: make build/$1"
        else bad "example builds: make build/$1"; sed 's/^/    /' "$R/ex_$1.out" | head -20; fi
        return
    fi
    mkdir -p "$R/ex"
    if [ -f "examples/$1.cpp" ]; then
        ${CXX:-c++} -std=c++17 -O0 $W "examples/$1.cpp" -lm -o "$R/ex/$1" >"$R/ex_$1.out" 2>&1
    else
        $CC -std=c99 -O0 $W "examples/$1.c" -lm -o "$R/ex/$1" >"$R/ex_$1.out" 2>&1
    fi
    if [ $? -eq 0 ]; then ok "example builds: examples/$1 at -O0 -Werror"
    else bad "example builds: examples/$1 at -O0 -Werror"; sed 's/^/    /' "$R/ex_$1.out" | head -20; fi
}
# the binary of example NAME that job_ex built
exbin() { if [ -x "$R/ex/$1" ]; then echo "$R/ex/$1"; else echo "build/$1"; fi; }
# the front door (issue 42), a few seconds in all: the demo at its defaults against the explicit
# reference it runs itself (runout and height within 10%); explicit runs at their stable step by
# default; every example's --help exits 0 and lists each flag it takes, once; game_loop creates
# its picture folder
job_front_door() {
    [ -x build/sand_column ] || { bad "front door: build/sand_column was not built"; return; }
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
        if ! "$(exbin "$e")" --help >build/example_help.txt 2>&1; then bad "example_help: $e --help exits $?"; continue; fi
        # a flag defined twice: on two lines of the help that begin with it
        dup=$(grep -E '^ *--' build/example_help.txt | while read -r line; do
            echo "$line" | grep -oE -- '--[A-Za-z0-9-]+' | sort -u; done | sort | uniq -d | tr '\n' ' ')
        # a flag the source takes that the help does not name
        case $e in sand_column|snowball) src="examples/$e.c examples/common/pn_example.h";; metal_frame) src="examples/$e.c examples/common/pn_frame.h";; game_loop) src=examples/$e.cpp;; *) src=examples/$e.c;; esac
        # shellcheck disable=SC2086
        miss=$(grep -ohE '"--[A-Za-z0-9-]+"' $src | tr -d '"' | sort -u | while read -r f; do
            grep -qE -- "(^|[^A-Za-z0-9-])$f([^A-Za-z0-9-]|$)" build/example_help.txt || echo "$f"; done | tr '\n' ' ')
        if [ -z "$dup" ] && [ -z "$miss" ]; then ok "example_help: $e"
        else bad "example_help: $e lists twice: '$dup'; takes but does not list: '$miss'"; fi
    done
    rm -rf build/example_png_dir
    if "$(exbin game_loop)" --frames 1 --res 16 --png build/example_png_dir/sub >build/example_png.log 2>&1 &&
        [ -d build/example_png_dir/sub ]; then
        ok "example_game_loop_png_mkdir"
    else
        bad "example_game_loop_png_mkdir: build/example_png_dir/sub not created"; sed 's/^/    /' build/example_png.log | tail -5
    fi
}
# every C block of README.md builds and runs (tests/readme_snippets.sh)
job_readme() {
    sh tests/readme_snippets.sh >build/readme_snippets.log 2>&1
    tally readme_snippets build/readme_snippets.log $?
}
# one version everywhere: each header's banner, PN_VERSION_MAJOR/_MINOR and CHANGELOG.md's newest entry
job_version() {
    v=$(sed -n 's/^#define PN_VERSION_MAJOR \([0-9]*\)$/\1/p' plastinet.h).$(sed -n 's/^#define PN_VERSION_MINOR \([0-9]*\)$/\1/p' plastinet.h)
    c=$(sed -n 's/^## \([0-9][0-9.]*\).*/\1/p' CHANGELOG.md | head -n 1)
    vok=1
    for h in plastinet.h plastinet_mpm.h plastinet_rom.h; do
        head -n 1 "$h" | grep -q " - v$v - " || { vok=0; echo "    $h: banner $(head -n 1 "$h" | cut -c1-40) is not v$v"; }
    done
    [ "$c" = "$v" ] || { vok=0; echo "    CHANGELOG.md's newest entry is $c, PN_VERSION is $v"; }
    if [ $vok = 1 ]; then ok "version $v: banners, PN_VERSION and CHANGELOG.md agree"; else bad "version: banners, PN_VERSION and CHANGELOG.md disagree"; fi
}
# the same bits from every compiler (tests/cross_compiler.sh: gcc, g++, clang at -O2 with
# -ffp-contract=off and -Werror, every integrator and energy); skipped with fewer than two compilers
job_cross() {
    sh tests/cross_compiler.sh >build/cross_compiler.log 2>&1
    tally cross_compiler build/cross_compiler.log $?
}
# explicit MPM in float against double (bench/bench_explicit.c, the 88-line MLS-MPM scene
# with 3000 particles, 0.15 s through the impact): the elastic blocks' mean height agrees to
# 5e-4 (float resolves a height of 0.2 m to 1.5e-8 m, and a step moves a particle 1e-4 m or
# less, so each step's displacement is rounded by up to ~1e-4 of itself; over 1500 steps of
# slowly varying velocity those roundings add up to a few 1e-4: measured 7.7e-5, and 2.1e-4
# with one more wall row held; double is not sensitive there: E x (1 + 1e-6) or FMA on/off
# move it < 1e-5); for the snow, which fractures (chaotic), the float-double gap is printed
# beside what a change of E by 1e-6 does in double (docs/results.md: float works at the
# precision the scene allows)
job_float_check() {
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
}
# the browser demo (examples/web, WebAssembly) in headless Chromium: tests/web_test.py. Runs
# whenever emscripten, chromium and chromedriver are installed (Debian: apt-get install -y
# emscripten chromium chromium-driver); CI requires them.
job_web() {
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
}

if [ "$1" = --job ]; then # JOB [ARG]: one job, its lines then its "N passed, N failed"
    FILTER=$RUN_FILTER
    case $2 in
        cc:*) job_cc "${2#cc:}";;
        t:*) job_t "${2#t:}";;
        ex:*) job_ex "${2#ex:}";;
        *) "job_$2";;
    esac
    summary
    exit 0
fi

# ---- the driver ----------------------------------------------------------------------------------
RUN_FILTER=$1
export RUN_FILTER
rm -f "$R"/*.log "$R"/t/*.log "$R/times"
rm -rf "$R/ex"
# run_queue: run the job names read from stdin, TEST_JOBS at a time, each into its log (xargs
# starts each as a slot frees, reading the names as they come)
run_queue() {
    # shellcheck disable=SC2016
    xargs -P "${TEST_JOBS:-2}" -n 1 sh -c 't0=$(date +%s.%N); sh tests/run.sh --job "$1" >"build/run/$(echo "$1" | tr ":" "_").log" 2>&1; echo "$(date +%s.%N) $t0 $1" >>build/run/times' sh
}
# phase 1, the longest first (CPU seconds on one core, measured: examples 15-30 each with make,
# 0.5-3 at -O0, a compile
# check about 20, test_main's build about 45)
: >"$R/phase1"
if [ -z "$SANITIZE" ] && [ -z "$1" ]; then
    cc_list >"$R/cc.list"
    echo web >>"$R/phase1"
    echo build_main >>"$R/phase1"
    echo cross >>"$R/phase1"
    for e in $EXAMPLES; do echo "ex:$e" >>"$R/phase1"; done
    echo readme >>"$R/phase1"
    k=1
    while [ $k -le "$(wc -l <"$R/cc.list")" ]; do echo "cc:$k" >>"$R/phase1"; k=$((k + 1)); done
    for j in float_check crosscheck float render lanes_native lanes_portable version; do echo $j >>"$R/phase1"; done
else
    for j in build_main float render; do echo $j >>"$R/phase1"; done
fi
# phase 2: test_main's tests (the list in registration order; run the slowest first), the front
# door; written once build_main's job has ended (its log's last line is its summary; at most
# an hour, should that job die without one)
phase2() {
    k=0
    while ! tail -n 1 "$R/build_main.log" 2>/dev/null | grep -q '^[0-9]* passed, [0-9]* failed$' && [ $k -lt 3600 ]; do
        sleep 1; k=$((k + 1))
    done
    : >"$R/phase2"
    [ -z "$SANITIZE" ] && [ -z "$1" ] && echo front_door >>"$R/phase2"
    if [ -x "build/test_main$suffix" ]; then
        "./build/test_main$suffix" --list ${1:+"$1"} >"$R/tests"
        # the slowest first, then the rest in order (wall seconds measured in make test-all and
        # make test-sanitize: build/run/times)
        for n in multigrid_default_3d fem_explicit_implicit rom_cylinder_vs_mpm stress_coarse stress_anderson \
            fem_self_contact_3d transfer_threads_identical couple_explicit_implicit implicit_pnet_sand_column \
            implicit_failed_step_no_trace scene_stable_dt stress_hydrostatic couple_threads_identical; do
            grep -qx "$n" "$R/tests" && echo "t:$n" >>"$R/phase2"
        done
        sed 's/^/t:/' "$R/tests" | grep -vxF -f "$R/phase2" >>"$R/phase2"
    fi
    cat "$R/phase2"
}
{ cat "$R/phase1"; phase2 "$1"; } | run_queue
# the logs, in a fixed order: phase 1's, then the test_main tests in registration order, then
# the front door
print_log() { # JOB
    f=$R/$(echo "$1" | tr ":" "_").log
    if [ -f "$f" ]; then tally "$1" "$f" 0; else bad "$1: no log"; fi
}
for j in $(cat "$R/phase1"); do
    case $j in build_main) ;; *) print_log "$j";; esac
done
print_log build_main
[ -f "$R/tests" ] && for n in $(cat "$R/tests"); do print_log "t:$n"; done
grep -qx front_door "$R/phase2" && print_log front_door
# each job's wall seconds: build/run/times ("end start job"); CI prints the slowest, so that the
# time budget (make test 5 min, CI 30) can be kept by looking
if [ "${CI:-}" = true ] && [ -f "$R/times" ]; then
    echo "slowest jobs (wall s):"
    awk '{ printf "  %7.1f %s\n", $1 - $2, $3 }' "$R/times" | sort -rn | head -12
fi
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
