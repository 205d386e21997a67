#!/bin/sh
# The implicit energies in a scene: the sand column at aspect ratios 0.5 to 8, every energy at
# dt 1e-3 s and 1/60 s, against the explicit reference at its stable step (build/sand_column
# runs both). Each row: runout and final height over the reference's, the min/max mass IoU of
# the two deposits, the step-mean force error (pn_mpm_stats.force_error; the stress formulation
# has none), Newton iterations per step and wall seconds. The first row of each aspect is the
# explicit run at a fixed step below the stable one: how converged the reference is in dt.
#
#   sh bench/energies_in_scenes.sh [--dim 2|3] [--aspects "0.5 1 2 4 8"] [--seconds S]
#                                  [--energies "pnet dp lagged stress"] [--dts "1e-3 1/60"]
#                                  [--pnet-flags "..."] [--out FILE]
#
# --pnet-flags go to the PlasticityNet rows' sand_column (another model: "--model sand_2d_fy
# --regularizer -1"); --dts picks the steps (1/60 is 1/60 s).
#
# make bench-energies runs it (2D); docs/results.md quotes the tables.
set -e
args=""
for a in "$@"; do
    case "$a" in *" "*) args="$args \"$a\"" ;; *) args="$args $a" ;; esac
done
dim=2
aspects="0.5 1 2 4 8"
energies="pnet pnet2 dp lagged stress"
seconds=1
out=""
dts="1e-3 1/60"
pnet_flags=""
while [ $# -gt 0 ]; do
    case "$1" in
    --dim) dim=$2; shift 2 ;;
    --aspects) aspects=$2; shift 2 ;;
    --energies) energies=$2; shift 2 ;;
    --seconds) seconds=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --dts) dts=$2; shift 2 ;;
    --pnet-flags) pnet_flags=$2; shift 2 ;;
    *) echo "usage: energies_in_scenes.sh [--dim 2|3] [--aspects LIST] [--energies LIST] [--seconds S] [--dts LIST] [--pnet-flags S] [--out FILE]" >&2; exit 2 ;;
    esac
done
[ -x build/sand_column ] || make build/sand_column >&2
[ -n "$out" ] || out=bench/results/energies_in_scenes_${dim}d.md
mkdir -p "$(dirname "$out")"
frames=$(awk "BEGIN { print int($seconds * 30 + 0.5) }")

field() { # field NAME JSON
    printf '%s\n' "$2" | sed -n "s/.*\"$1\": \"*\([^,\"}]*\).*/\1/p"
}

# the column: tall ones are narrower, on a finer grid (the same particles per width)
geometry() { # geometry ASPECT -> flags
    if [ "$dim" = 2 ]; then
        if awk "BEGIN { exit !($1 > 4) }"; then echo "--width 0.06 --res 128"; else echo "--width 0.12 --res 64"; fi
    else
        if awk "BEGIN { exit !($1 > 2) }"; then echo "--width 0.06 --res 48 --domain 0.5"; else echo "--width 0.12 --res 24"; fi
    fi
}

{
    echo "# The implicit energies in the sand column, ${dim}D, ${seconds} s"
    echo
    echo "\`sh bench/energies_in_scenes.sh$args\` at $(git rev-parse --short HEAD 2>/dev/null || echo '?'), $(date -u +%Y-%m-%d)."
    echo "Every ratio against the explicit reference at its stable step, run beside each row."
    echo
    echo "| aspect | particles | run | dt (s) | passes | runout | height | IoU | force error | Newton / step | wall s | reference wall s |"
    echo "|---|---|---|---|---|---|---|---|---|---|---|---|"
} > "$out"

row() { # row ASPECT GEOMETRY LABEL DT PASSES FLAGS...
    r_a=$1 r_geo=$2 r_label=$3 r_dt=$4 r_passes=$5
    shift 5
    # shellcheck disable=SC2086
    j=$(build/sand_column --dim "$dim" --aspect "$r_a" $r_geo --frames "$frames" --quiet --force-error "$@" 2>&1 | tail -1) || true
    case "$j" in
    "{"*) ;;
    *) echo "| $r_a | | $r_label | $r_dt | $r_passes | failed: $(printf '%s' "$j" | cut -c1-80) | | | | | | |" >> "$out"; return ;;
    esac
    fe=$(field force_error "$j")
    [ "$(field formulation "$j")" = energy ] || fe="-"
    echo "| $r_a | $(field particles "$j") | $r_label | $r_dt | $r_passes | $(field runout_ratio "$j") | $(field height_ratio "$j") | $(field mass_iou_minmax "$j") | $fe | $(field newton_per_step "$j") | $(field wall_s "$j") | $(field reference_wall_s "$j") |" >> "$out"
}

for a in $aspects; do
    geo=$(geometry "$a")
    row "$a" "$geo" "explicit, fixed step" 5e-5 - --integrator explicit --dt 5e-5
    for t in $dts; do
        dt=$t
        [ "$t" = 1/60 ] && dt=0.016666666666666666
        for e in $energies; do
            case "$e" in
            # shellcheck disable=SC2086
            pnet) row "$a" "$geo" "PlasticityNet" "$t" 1 --energy pnet --dt "$dt" $pnet_flags ;;
            # shellcheck disable=SC2086
            pnet2) row "$a" "$geo" "PlasticityNet" "$t" 2 --energy pnet --fixed-point 2 --dt "$dt" $pnet_flags ;;
            dp) row "$a" "$geo" "frozen-yield DP" "$t" 1 --energy dp --dt "$dt" ;;
            lagged) row "$a" "$geo" "lagged" "$t" 1 --energy lagged --dt "$dt" ;;
            stress) row "$a" "$geo" "stress formulation" "$t" - --dt "$dt" ;;
            *) echo "energies_in_scenes.sh: unknown energy $e" >&2; exit 2 ;;
            esac
        done
    done
done
echo "wrote $out"
