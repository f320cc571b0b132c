#!/bin/bash
# One 1M-step PPO run of the precision screen: variant (g1 | lin | net256), seed.
# configs/ppo.yml otherwise; the baseline (increment gain 0.5) is runs/gain/g0.5.
v=$1; s=$2
here=$(cd "$(dirname "$0")" && pwd)
cd "$(dirname "$0")/../../.." && source .venv/bin/activate   # the repository root
export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
case $v in
  g1) extra=(--env-kwargs increment_gain=1.0) ;;        # increment gain 1.0 instead of 0.5
  lin) extra=(--config "$here/ppo_lin.yml") ;;          # learning rate 3e-4 falling linearly to 0
  net256) extra=(--config "$here/ppo_net256.yml") ;;    # [256, 256] networks instead of [64, 64]
  *) echo "unknown variant $v"; exit 2 ;;
esac
out=runs/screen/$v/seed_$s
mkdir -p "$(dirname "$out")"
if [ -f "$out/final_agent/agent.json" ]; then   # finished: kept (remove it to train again)
  echo "$(date -u +%T) kept v=$v s=$s (finished)"; exit 0
fi
rm -rf "$out"   # an unfinished run starts over (train.py refuses to mix two runs in one folder)
start=$(date +%s)
python train.py --algo ppo --seed "$s" --timesteps 1000000 "${extra[@]}" --out "$out" --no-progress \
  > "runs/screen/${v}_s${s}.log" 2>&1
rc=$?
echo "$(date -u +%T) done v=$v s=$s rc=$rc wall=$(( $(date +%s) - start ))s"
