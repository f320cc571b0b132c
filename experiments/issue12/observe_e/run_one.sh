#!/bin/bash
# One 1M-step PPO run of the observation probe: variant (params | eccentricity), seed.
# configs/ppo.yml otherwise (increment gain 0.5, observe_params false there).
v=$1; s=$2
cd "$(dirname "$0")/../../.." && source .venv/bin/activate   # the repository root
export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
case $v in
  params) kw="observe_params=True" ;;
  eccentricity) kw="observe_params=eccentricity" ;;
  *) echo "unknown variant $v"; exit 2 ;;
esac
out=runs/observe/$v/seed_$s
mkdir -p $(dirname $out)
if [ -f "$out/final_agent/agent.json" ]; then   # finished: kept (remove it to train again)
  echo "$(date -u +%T) kept v=$v s=$s (finished)"; exit 0
fi
rm -rf "$out"   # an unfinished run starts over (train.py refuses to mix two runs in one folder)
start=$(date +%s)
python train.py --algo ppo --seed $s --timesteps 1000000 --env-kwargs $kw --out $out --no-progress > runs/observe/${v}_s${s}.log 2>&1
rc=$?
echo "$(date -u +%T) done v=$v s=$s rc=$rc wall=$(( $(date +%s) - start ))s"
