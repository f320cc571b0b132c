#!/bin/bash
g=$1; s=$2
cd /work/main && source .venv/bin/activate
export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
out=/work/runs/gain/g${g}/seed_${s}
mkdir -p $(dirname $out)
python train.py --algo ppo --seed $s --timesteps 1000000 --env-kwargs increment_gain=$g --out $out --no-progress > /work/runs/gain/g${g}_s${s}.log 2>&1
echo "$(date -u +%T) done g=$g s=$s rc=$?"
