#!/usr/bin/env bash
# DeLaN's development measurements on results/arms/README.md, made by steps: the optimiser's grid, the
# network's size, the warm-up and V's network (shared with Λ or its own). Every fit is scored on data that no
# published run trains or tests on: generated samples of seed 2000 for the Panda and the UR5 (the runs'
# test samples come from seeds 1000 to 1009), and for the characters three of the 17 training characters
# (g, r and w: those that follow the test characters e, q and v), trained on the other 14.
#
# Each fit's record goes to NAME.json beside this file; a record already there is kept, so that an
# interrupted run goes on where it stopped. From the repository's root:
#
#   bash results/arms/development/make.sh           # the fits, by steps: the same numbers on any machine
#   bash results/arms/development/make.sh timing    # the compiled loss's timings: run on a quiet machine
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
py=${PYTHON:-python}
data=$(mktemp -d)
trap 'rm -rf "$data"' EXIT

generated() {  # SYSTEM: 32,000 training samples of seed 0 and 4,000 validation samples of seed 2000
    [ -e "$data/$1_train.csv" ] && return
    $py -m bench data --system "$1" --n 32000 --seed 0 --out "$data/$1_train.csv" >/dev/null
    $py -m bench data --system "$1" --n 4000 --seed 2000 --out "$data/$1_test.csv" >/dev/null
}

characters() {  # the characters' training set, less g, r and w, which validate
    [ -e "$data/characters_train.csv" ] && return
    gzip -dc systems/data/delan_characters.csv.gz | sed '1s/^character,t,/trajectory,time,/' > "$data/all.csv"
    awk -F, 'NR == 1 || ($1 !~ /^[eqvgrw]$/)' "$data/all.csv" > "$data/characters_train.csv"
    awk -F, 'NR == 1 || ($1 ~ /^[grw]$/)' "$data/all.csv" > "$data/characters_test.csv"
}

fit() {  # NAME DATA SYSTEM STEPS SEED [--set NAME=VALUE ...]
    local name=$1 which=$2 system=$3 steps=$4 seed=$5
    shift 5
    [ -e "$here/$name.json" ] && return
    case $which in characters) characters ;; *) generated "$which" ;; esac
    echo "$name"
    $py -m bench fit --system "$system" --method delan --experiment indirect --train "$data/${which}_train.csv" \
        --test "$data/${which}_test.csv" --steps "$steps" --seed "$seed" "$@" --json "$here/$name.json" >/dev/null
}

if [ "${1:-}" = timing ]; then
    # 2,000 steps eager, then compiled with an empty compile cache, then compiled with the cache it left
    fit timing_eager panda panda 2000 0 --set compile=false
    export TORCHINDUCTOR_CACHE_DIR="$data/inductor"
    fit timing_compiled_cold panda panda 2000 0
    fit timing_compiled_warm panda panda 2000 0
    exit
fi

# the optimiser: Adam's rate, AMSGrad and the batch on the Panda (the default: 1e-2, no AMSGrad, 256)
for lr in 5e-4 2e-3 3e-3 5e-3 1e-2 2e-2; do
    fit "optimiser_2000_b512_amsgrad_lr$lr" panda panda 2000 0 --set batch_size=512 --set amsgrad=true --set lr=$lr
done
fit optimiser_6000_b512_amsgrad_lr1e-2 panda panda 6000 0 --set batch_size=512 --set amsgrad=true
for lr in 1e-2 2e-2; do
    fit "optimiser_6000_b512_lr$lr" panda panda 6000 0 --set batch_size=512 --set lr=$lr
    fit "optimiser_12000_b256_lr$lr" panda panda 12000 0 --set lr=$lr
done
fit optimiser_20000_b128_lr1e-2 panda panda 20000 0 --set batch_size=128

# the network's size on the Panda, 2,000 steps (the authors': 2 layers of 64 units)
fit size_64x2_2000 panda panda 2000 0
for hidden in 128 256; do
    fit "size_${hidden}x2_2000" panda panda 2000 0 --set hidden=$hidden
done
fit size_64x3_2000 panda panda 2000 0 --set layers=3

# the warm-up on the characters, every seed
for seed in 0 1 2 3 4 5 6 7 8 9; do
    for warmup in 0 300 1000; do
        fit "warmup_${warmup}_seed$seed" characters delan_characters 3000 "$seed" --set warmup=$warmup
    done
done

# V's network: shared with Λ or its own (the default), on the UR5, the Panda and the characters
for potential in shared separate; do
    for seed in 0 3 5; do
        fit "potential_${potential}_ur5_6000_seed$seed" ur5 ur5 6000 "$seed" --set potential=$potential
    done
    for seed in 0 5; do
        fit "potential_${potential}_ur5_12000_seed$seed" ur5 ur5 12000 "$seed" --set potential=$potential
    done
    for steps in 6000 12000; do
        fit "potential_${potential}_panda_${steps}_seed0" panda panda "$steps" 0 --set potential=$potential
    done
    fit "potential_${potential}_characters_3000_seed8" characters delan_characters 3000 8 --set potential=$potential
done
fit potential_shared_ur5_6000_seed5_shift2 ur5 ur5 6000 5 --set potential=shared --set diagonal_shift=2
fit potential_shared_ur5_6000_seed5_warmup1500 ur5 ur5 6000 5 --set potential=shared --set warmup=1500
