#!/bin/bash
# Continue one shipped 3M-step PPO run (seed K of `python train.py --algo ppo --seeds 10`)
# to 6M env steps: a copy of its run folder, `train.py --resume --timesteps 3000000`.
s=$1
cd /work/main && source .venv/bin/activate
export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
src=/work/runs/ppo_g05/seed_$s
out=/work/runs/ppo_6m/seed_$s
mkdir -p /work/runs/ppo_6m
[ -d "$out" ] || cp -r "$src" "$out"
start=$(date +%s)
python train.py --algo ppo --seed "$s" --resume --timesteps 3000000 --out "$out" --no-progress \
  > "/work/runs/ppo_6m/seed_${s}.log" 2>&1
rc=$?
echo "$(date -u +%T) done s=$s rc=$rc wall=$(( $(date +%s) - start ))s"
