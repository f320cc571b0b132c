#!/bin/bash
# One SAC run of the gSDE probe: seed. sac_sde.yml is configs/sac.yml with [64, 64]
# networks (about 6 ms per gradient step on one core instead of 19) and gSDE
# exploration (use_sde, a new noise matrix every 8 steps) instead of i.i.d. noise.
s=$1
here=$(cd "$(dirname "$0")" && pwd)
cd "$(dirname "$0")/../../.." && source .venv/bin/activate   # the repository root
export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
out=runs/sac_sde/seed_$s
mkdir -p runs/sac_sde
if [ -f "$out/final_agent/agent.json" ]; then   # finished: kept (remove it to train again)
  echo "$(date -u +%T) kept s=$s (finished)"; exit 0
fi
rm -rf "$out"   # an unfinished run starts over (train.py refuses to mix two runs in one folder)
start=$(date +%s)
python train.py --algo sac --seed "$s" --timesteps 800000 --config "$here/sac_sde.yml" --out "$out" --no-progress \
  > "runs/sac_sde/s${s}.log" 2>&1
rc=$?
echo "$(date -u +%T) done s=$s rc=$rc wall=$(( $(date +%s) - start ))s"
