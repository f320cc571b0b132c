#!/bin/bash
# Behaviour cloning on the shared mpc dataset (docs/distillation.md, "Behaviour cloning
# on two million labels"): the fits and their default-suite scores, one training seed.
# Needs runs/distill_data/ from experiments/issue36/make_data.sh.
# usage: experiments/issue36/bc.sh NAME   (plain | a_symlog | all_symlog | a_symlog_wide | a_symlog_dagger)
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
source experiments/issue36/set_a.sh   # parts A | B | AB
fit=(--iterations 0 --epochs 40 --batch-size 2048 --check-episodes 0 --seed 0)
case $1 in
  plain) args=(--data $(parts AB) "${fit[@]}") ;;
  a_symlog) args=(--data $(parts A) "${fit[@]}" --symlog-scale 1e-4) ;;
  all_symlog) args=(--data $(parts AB) "${fit[@]}" --symlog-scale 1e-4) ;;
  a_symlog_wide) args=(--data $(parts A) --iterations 0 --epochs 80 --batch-size 2048
                       --check-episodes 0 --seed 0 --symlog-scale 1e-4 --net-arch 512 512) ;;
  a_symlog_dagger) args=(--data $(parts A) --iterations 2 --episodes 10 --beta-decay 0
                         --gate 0.1 --drop-failed --epochs 40 --batch-size 2048
                         --check-episodes 0 --seed 0 --symlog-scale 1e-4) ;;
  *) echo "unknown fit $1" >&2; exit 2 ;;
esac
if [ ! -f "runs/bc/$1/agent.json" ]; then   # a finished fit is kept (remove it to fit again)
  rm -rf "runs/bc/$1"   # an unfinished fit starts over (train.py distill has no resume)
  python train.py distill "${args[@]}" --out "runs/bc/$1"
fi
python evaluate.py "runs/bc/$1" "filtered:runs/bc/$1" --seeds 3 --no-plots \
  --out "runs/bc_eval/$1"
