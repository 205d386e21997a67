#!/bin/sh
# The classic 88-line MLS-MPM program (Hu et al. 2018) beside bench_explicit, on its own scene, in
# one run: particle-steps per second per core for each grid (n 80 and 256), precision (float,
# double) and flag set (-O2; -O3 -march=native), and our ratio to it.
#
# Usage: MLS88_DIR=/path/to/copy [REPS=2] bench/mls88_side_by_side.sh [seconds] [out.md]
# REPS: alternating runs of each program per configuration; the table has the best of each.
# seconds: simulated time per run [0.1: through the impacts]; the step is the program's 1e-4 s
# at n = 80 and 2e-5 s at n = 256 (its 1e-4 s is unstable there), 1000 and 5000 steps.
# MLS88_DIR holds mls-mpm88.cpp and taichi.h (the program's release archive, or its repository
# with an amalgamated taichi.h). Nothing is downloaded and none of it enters this repository:
# the script writes a headless copy to build/ (its GUI main replaced by a timing loop written
# here; the particle count per square, the grid, the step and the snow switch made parameters)
# and builds it beside ours with the same flags. Newer taichi.h amalgamations renamed clamp to
# ti_clamp; the copy follows whichever the header has. Needs a C++14 compiler and libX11 (which
# the amalgamated header links against even without a window).
set -e
cd "$(dirname "$0")/.."
sim=${1:-0.1}
out=${2:-build/mls88_side_by_side.md}
reps=${REPS:-2}
[ -n "$MLS88_DIR" ] && [ -f "$MLS88_DIR/mls-mpm88.cpp" ] && [ -f "$MLS88_DIR/taichi.h" ] || {
    echo "mls88_side_by_side: set MLS88_DIR to a folder with mls-mpm88.cpp and taichi.h" >&2
    exit 2
}
CXX=${CXX:-c++}
CC=${CC:-cc}
mkdir -p build
src=build/mls88_headless.cpp
clamp=clamp
grep -q "ti_clamp" "$MLS88_DIR/taichi.h" && ! grep -q "T clamp(" "$MLS88_DIR/taichi.h" && clamp=ti_clamp
{
    echo "#include \"$(cd "$MLS88_DIR" && pwd)/taichi.h\""
    sed -e '/^#define TC_IMAGE_IO/d' -e '/#include "taichi.h"/d' -e '/^int main()/,$d' \
        -e 's/i < 1000; i++/i < MLS88_PER_OBJECT; i++/' -e 's/const int n = 80 /const int n = MLS88_N /' \
        -e 's/dt = 1e-4_f/dt = (real)MLS88_DT/' -e 's/bool plastic = true;/bool plastic = MLS88_PLASTIC;/' \
        -e "s/ clamp(/ $clamp(/" "$MLS88_DIR/mls-mpm88.cpp"
    cat <<'EOF'
#include <chrono>
int main(int argc, char **argv) { /* the timing loop of mls88_side_by_side.sh */
    int steps = argc > 1 ? atoi(argv[1]) : 1000;
    add_object(Vec(0.55, 0.45), 0xED553B);
    add_object(Vec(0.45, 0.65), 0xF2B134);
    add_object(Vec(0.55, 0.85), 0x068587);
    for (int i = 0; i < 10; i++) advance(dt);
    auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < steps; i++) advance(dt);
    double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    double y = 0;
    for (auto &p : particles) y += p.x.y;
    printf("psteps_per_s=%.4g mean_y=%.6f\n", particles.size() * (double)steps / s, y / particles.size());
}
EOF
} >$src
{
    echo "# The 88-line MLS-MPM program beside bench_explicit: $sim s of its scene (30k particles), one core, best of $reps alternating runs each"
    echo
    echo "| grid | real | scene | flags | 88-line, particle-steps/s | plastinet | ratio | mean height 88-line / plastinet |"
    echo "|---|---|---|---|---|---|---|---|"
} >"$out"
for flags in "-O2" "-O3 -march=native"; do
    tag=$(echo "$flags" | tr -d ' =-')
    for real in float double; do
        d=""; pd=""
        [ $real = double ] && d="-DTC_USE_DOUBLE" || pd="-DPN_REAL=float"
        # shellcheck disable=SC2086
        $CC -std=c99 $flags $pd bench/bench_explicit.c -lm -o build/bench_explicit_$tag$real
        for n in 80 256; do
            dt=$(awk -v n=$n 'BEGIN { print (n <= 80 ? 1e-4 : 1e-4 * 80 / n * 0.64) }')
            steps=$(awk -v s="$sim" -v dt="$dt" 'BEGIN { printf "%d", s / dt + 0.5 }')
            for scene in snow jelly; do
                plastic=true; jelly=""
                [ $scene = jelly ] && plastic=false && jelly=--jelly
                bin=build/mls88_$tag${real}_$n$scene
                # shellcheck disable=SC2086
                $CXX -std=c++14 $flags $d -DMLS88_N=$n -DMLS88_PER_OBJECT=10000 -DMLS88_DT=$dt -DMLS88_PLASTIC=$plastic \
                    $src -o $bin -lpthread -lX11 2>build/mls88_build.log
                tr=0; orate=0; rep=0
                while [ $rep -lt "$reps" ]; do # alternating runs, the best of each (this machine's speed drifts)
                    theirs=$(./$bin "$steps" | tail -n 1)
                    ours=$(build/bench_explicit_$tag$real --n $n --steps "$steps" $jelly --threads 1)
                    tr=$(echo "$theirs" | sed 's/.*psteps_per_s=\([^ ]*\).*/\1/' | awk -v b="$tr" '{ print ($1 > b ? $1 : b) }')
                    orate=$(echo "$ours" | sed 's/.*psteps_per_s=\([^ ]*\).*/\1/' | awk -v b="$orate" '{ print ($1 > b ? $1 : b) }')
                    rep=$((rep + 1))
                done
                ty=$(echo "$theirs" | sed 's/.*mean_y=\([^ ]*\).*/\1/')
                oy=$(echo "$ours" | sed 's/.*mean_y=\([^ ]*\).*/\1/')
                ratio=$(awk -v a="$orate" -v b="$tr" 'BEGIN { printf "%.2f", a / b }')
                line="| $n | $real | $scene | $flags | $tr | $orate | $ratio | $ty / $oy |"
                echo "$line" >>"$out"
                echo "$line"
            done
        done
    done
done
echo "written: $out"
