#!/bin/sh
# Same bits across compilers (plastinet.h, THREADS AND DETERMINISM): builds
# tests/cross_compiler_driver.c with every compiler found among gcc, clang and g++ (as C++) at
# -O2 -ffp-contract=off (and -Wall -Wextra -Werror -pedantic: these are make test's clang and C++
# builds of the headers), runs each build and compares the hash of the particle state after a
# few steps of every integrator/energy combination the driver knows.
# Usage: tests/cross_compiler.sh [name-filter]
#        CC_OPT=-O3 CC_LIST="gcc clang clang++" tests/cross_compiler.sh   (defaults: -O2, gcc clang g++)
# Prints one "ok   cross-compiler: NAME" or "FAIL cross-compiler: NAME" line per combination;
# last line: N passed, N failed ("skip ..." and 0 passed, 0 failed with fewer than 2 compilers).
cd "$(dirname "$0")/.." || exit 1
mkdir -p build
opt=${CC_OPT:--O2}
dir=build/cross_compiler
mkdir -p "$dir"
rm -f "$dir"/*.out "$dir"/*.log

# build with every compiler found (in parallel), then run the builds (in parallel)
built=
for cc in ${CC_LIST:-gcc clang g++}; do
    command -v "$cc" >/dev/null 2>&1 || { echo "skip $cc (not installed)"; continue; }
    case $cc in *++) std="-x c++ -std=c++11";; *) std="-std=c99";; esac
    tag=$(echo "$cc" | tr '+' 'x')
    # shellcheck disable=SC2086
    ( $cc $std $opt -Wall -Wextra -Werror -pedantic -ffp-contract=off tests/cross_compiler_driver.c -lm -o "$dir/$tag" \
        >"$dir/$tag.log" 2>&1 && ./"$dir/$tag" "$@" >"$dir/$tag.out" 2>>"$dir/$tag.log" ) &
    built="$built $tag"
done
wait

passed=0
failed=0
ok=
for tag in $built; do
    if [ -s "$dir/$tag.out" ]; then
        ok="$ok $tag"
    else
        echo "FAIL cross-compiler: build or run with $tag"
        sed 's/^/    /' "$dir/$tag.log" | head -20
        failed=$((failed + 1))
    fi
done
# shellcheck disable=SC2086
set -- $ok
if [ $# -lt 2 ]; then
    echo "skip cross-compiler: fewer than two compilers built and ran the driver (${ok# })"
    echo "$passed passed, $failed failed"
    [ "$failed" -eq 0 ]
    exit $?
fi

# one line per combination: NAME HASH ...; the first build is the reference
ref=$1
# shellcheck disable=SC2013
for name in $(awk '{print $1}' "$dir/$ref.out"); do
    want=$(awk -v n="$name" '$1 == n {print $2}' "$dir/$ref.out")
    differ=
    for tag in "$@"; do
        got=$(awk -v n="$name" '$1 == n {print $2}' "$dir/$tag.out")
        [ "$got" = "$want" ] || differ="$differ $tag"
    done
    if [ "$want" = error ]; then
        failed=$((failed + 1))
        echo "FAIL cross-compiler: $name (the step failed with $ref: $(awk -v n="$name" '$1 == n' "$dir/$ref.out"))"
    elif [ -z "$differ" ]; then
        passed=$((passed + 1))
        echo "ok   cross-compiler: $name ($*, $opt)"
    else
        failed=$((failed + 1))
        echo "FAIL cross-compiler: $name ($ref !=${differ} at $opt -ffp-contract=off)"
        for tag in "$@"; do
            echo "    $tag: $(awk -v n="$name" '$1 == n' "$dir/$tag.out")"
        done
    fi
done
# every build must report the same set of combinations
for tag in "$@"; do
    if [ "$(awk '{print $1}' "$dir/$tag.out")" != "$(awk '{print $1}' "$dir/$ref.out")" ]; then
        failed=$((failed + 1))
        echo "FAIL cross-compiler: $tag ran other combinations than $ref"
    fi
done
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
