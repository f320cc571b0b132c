#!/bin/bash
# Continue one shipped 3M-step PPO run (seed K of `python train.py --algo ppo --seeds 10`)
# to 6M env steps: a copy of its run folder, `train.py --resume --timesteps 3000000`.
s=$1
cd "$(dirname "$0")/../../.." && source .venv/bin/activate   # the repository root
export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
src=runs/ppo/seed_$s   # the fan-out: python train.py --algo ppo --seeds 10 --out runs/ppo
out=runs/ppo_6m/seed_$s
mkdir -p runs/ppo_6m
[ -d "$out" ] || cp -r "$src" "$out"
start=$(date +%s)
python train.py --algo ppo --seed "$s" --resume --timesteps 3000000 --out "$out" --no-progress \
  > "runs/ppo_6m/seed_${s}.log" 2>&1
rc=$?
echo "$(date -u +%T) done s=$s rc=$rc wall=$(( $(date +%s) - start ))s"
