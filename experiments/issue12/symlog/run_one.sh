#!/bin/bash
# One 1M-step PPO run of the symlog-feature probe (configs/ppo.yml + symlog error features):
# seed [S]. S (default 1e-3 rad) is the scale of symlog(e / S); runs go to runs/symlog[_S].
s=$1; scale=${2:-1e-3}
cd "$(dirname "$0")/../../.." && source .venv/bin/activate   # the repository root
export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
folder=runs/symlog; [ "$scale" != 1e-3 ] && folder=runs/symlog_$scale
out=$folder/seed_$s
mkdir -p "$folder"
export SYMLOG_SCALE=$scale
start=$(date +%s)
python experiments/issue12/symlog/symlog.py train --seed "$s" --timesteps 1000000 --out "$out" \
  > "$folder/s${s}.log" 2>&1
rc=$?
echo "$(date -u +%T) done s=$s S=$scale rc=$rc wall=$(( $(date +%s) - start ))s"
