#!/bin/sh
# The fuzz targets (tests/fuzz/README.md): builds every tests/fuzz/fuzz_*.c into build/fuzz/
# and runs each for a fixed time on a copy of its corpus (tests/fuzz/corpus/<name>/, which
# this never changes), two at a time.
# Usage: tests/fuzz/run.sh [seconds_per_target]   (default 20: four targets take 40 s of
#        fuzzing on two cores, plus the builds)
#        tests/fuzz/run.sh --replay                 (each corpus file once: a regression test)
# Without clang's libFuzzer (or with --replay) the targets are built with $CC and
# tests/fuzz/standalone.c and replay their corpus instead.
# Last line: N passed, N failed
cd "$(dirname "$0")/../.." || exit 1
secs=${1:-20}
replay=0
[ "$secs" = --replay ] && replay=1
case $secs in --replay) ;; *[!0-9]* | "") echo "usage: tests/fuzz/run.sh [seconds_per_target | --replay]" >&2; exit 2;; esac
out=build/fuzz
mkdir -p "$out"
passed=0
failed=0
# PLASTINET_STATIC: the library's unused functions are not compiled (the builds take a
# fraction of the time); -Wno-unused-function goes with it
W="-std=c99 -Wall -Wextra -Werror -pedantic -Wno-unused-function -DPLASTINET_STATIC"
FUZZ_CC=${FUZZ_CC:-clang}
mode=standalone
if [ $replay = 0 ] && command -v "$FUZZ_CC" >/dev/null 2>&1; then
    printf '#include <stdint.h>\n#include <stddef.h>\nint LLVMFuzzerTestOneInput(const uint8_t *d, size_t n);\nint LLVMFuzzerTestOneInput(const uint8_t *d, size_t n) { (void)d; return (int)n * 0; }\n' >"$out/probe.c"
    if "$FUZZ_CC" -fsanitize=fuzzer "$out/probe.c" -o "$out/probe" >/dev/null 2>&1; then mode=libfuzzer; fi
fi
SCC=${CC:-cc}
san="-fsanitize=address,undefined -fno-sanitize-recover=all"
if [ $mode = standalone ]; then
    printf 'int main(void) { return 0; }\n' >"$out/probe.c"
    # shellcheck disable=SC2086
    "$SCC" $san "$out/probe.c" -o "$out/probe" >/dev/null 2>&1 || san=""
    echo "# fuzz: replaying the corpus once per target ($SCC${san:+ with sanitizers}, tests/fuzz/standalone.c)"
else
    echo "# fuzz: libFuzzer ($FUZZ_CC), $secs s per target, two at a time"
fi

# job NAME: build the target, then fuzz it (or replay its corpus); the status in $out/NAME.rc
job() {
    n=$1
    bin=$out/fuzz_$n
    log=$out/fuzz_$n.log
    if [ $mode = libfuzzer ]; then
        # shellcheck disable=SC2086
        if ! "$FUZZ_CC" $W -g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all \
            "tests/fuzz/fuzz_$n.c" -lm -o "$bin" >"$log" 2>&1; then echo build >"$out/fuzz_$n.rc"; return; fi
        rm -rf "$out/corpus_$n" && mkdir -p "$out/corpus_$n"
        [ -d "tests/fuzz/corpus/$n" ] && cp tests/fuzz/corpus/"$n"/* "$out/corpus_$n/" 2>/dev/null
        "./$bin" -max_total_time="$secs" -max_len=4096 -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
            -artifact_prefix="$out/fuzz_$n-" "$out/corpus_$n" >>"$log" 2>&1
        echo $? >"$out/fuzz_$n.rc"
    else
        # shellcheck disable=SC2086
        if ! "$SCC" $W -g -O1 $san tests/fuzz/standalone.c "tests/fuzz/fuzz_$n.c" -lm -o "$bin" >"$log" 2>&1; then
            echo build >"$out/fuzz_$n.rc"; return
        fi
        set -- tests/fuzz/corpus/"$n"/*
        [ -e "$1" ] || set --
        "./$bin" "$@" >>"$log" 2>&1
        echo $? >"$out/fuzz_$n.rc"
    fi
}
report() {
    n=$1
    rc=$(cat "$out/fuzz_$n.rc" 2>/dev/null)
    if [ "$rc" = 0 ]; then
        passed=$((passed + 1))
        if [ $mode = libfuzzer ]; then
            echo "ok   fuzz_$n ($(sed -n 's/^stat::number_of_executed_units: *//p' "$out/fuzz_$n.log") runs)"
        else
            echo "ok   fuzz_$n ($(tail -n 1 "$out/fuzz_$n.log"))"
        fi
    else
        failed=$((failed + 1))
        if [ "$rc" = build ]; then echo "FAIL fuzz_$n (build)"; else echo "FAIL fuzz_$n (exit $rc; log $out/fuzz_$n.log)"; fi
        grep -v '^INFO\|^#[0-9]' "$out/fuzz_$n.log" | head -30 | sed 's/^/    /'
        for a in "$out"/fuzz_"$n"-*; do [ -e "$a" ] && echo "    input: $a (add it to tests/fuzz/corpus/$n/)"; done
    fi
}

names=""
for src in tests/fuzz/fuzz_*.c; do
    [ -e "$src" ] || continue
    n=$(basename "$src" .c); n=${n#fuzz_}
    names="$names $n"
    rm -f "$out/fuzz_$n.rc" "$out"/fuzz_"$n"-*
done
# shellcheck disable=SC2086
set -- $names
while [ $# -gt 0 ]; do # two at a time (the machine's two cores), reported in order
    a=$1; shift
    b=""; [ $# -gt 0 ] && { b=$1; shift; }
    job "$a" &
    pa=$!
    [ -n "$b" ] && { job "$b" & pb=$!; }
    wait "$pa"; report "$a"
    [ -n "$b" ] && { wait "$pb"; report "$b"; }
done
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
