#!/bin/sh
# Every C block of README.md builds as written (and as C++), and each one with a main runs and
# exits 0: what a new user pastes works. Blocks without a main are compiled only.
# Last line: N passed, N failed.
cd "$(dirname "$0")/.." || exit 1
dir=build/readme
rm -rf "$dir"
mkdir -p "$dir"
awk -v dir="$dir" '
    /^```c$/ { n++; out = sprintf("%s/snippet_%d.c", dir, n); inside = 1; next }
    /^```/ { inside = 0; next }
    inside { print > out }
' README.md
CC=${CC:-cc}
W="-Wall -Wextra -Werror -pedantic"
passed=0
failed=0
for src in "$dir"/snippet_*.c; do
    [ -f "$src" ] || { echo "FAIL readme: no C block found"; failed=$((failed + 1)); break; }
    name=$(basename "$src" .c)
    bin="$dir/$name"
    if grep -q "int main" "$src"; then link="-lm -o $bin"; else link="-c -o $bin.o"; fi
    # shellcheck disable=SC2086
    if ! $CC -std=c99 -O2 $W -I. "$src" $link 2>"$bin.log"; then
        echo "FAIL readme: $name does not build as C99"; sed 's/^/    /' "$bin.log" | head -10
        failed=$((failed + 1)); continue
    fi
    if command -v c++ >/dev/null 2>&1 && ! c++ -x c++ -std=c++11 -O0 $W -I. -c "$src" -o "$bin.cpp.o" 2>"$bin.log"; then
        echo "FAIL readme: $name does not build as C++"; sed 's/^/    /' "$bin.log" | head -10
        failed=$((failed + 1)); continue
    fi
    if [ -x "$bin" ] && ! "./$bin" >"$bin.out" 2>&1; then
        echo "FAIL readme: $name exits non-zero"; sed 's/^/    /' "$bin.out" | head -10
        failed=$((failed + 1)); continue
    fi
    echo "ok   readme: $name"
    passed=$((passed + 1))
done
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
