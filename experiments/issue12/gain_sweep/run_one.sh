#!/bin/bash
# One 1M-step PPO run of the increment-gain sweep: gain, seed (jobs.txt lists all nine).
# configs/ppo.yml otherwise; runs go to runs/gain/g<gain>/seed_<seed> (repository root).
g=$1; s=$2
cd "$(dirname "$0")/../../.." && source .venv/bin/activate   # the repository root
export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
out=runs/gain/g${g}/seed_${s}
mkdir -p "$(dirname "$out")"
if [ -f "$out/final_agent/agent.json" ]; then   # finished: kept (remove it to train again)
  echo "$(date -u +%T) kept g=$g s=$s (finished)"; exit 0
fi
rm -rf "$out"   # an unfinished run starts over (train.py refuses to mix two runs in one folder)
start=$(date +%s)
python train.py --algo ppo --seed "$s" --timesteps 1000000 --env-kwargs increment_gain="$g" \
  --out "$out" --no-progress > "runs/gain/g${g}_s${s}.log" 2>&1
rc=$?
echo "$(date -u +%T) done g=$g s=$s rc=$rc wall=$(( $(date +%s) - start ))s"
