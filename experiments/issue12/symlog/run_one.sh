#!/bin/bash
# One 1M-step PPO run of the symlog-feature probe: seed [S]. agents/configs/ppo_symlog.yml
# (configs/ppo.yml plus `features: {name: symlog_errors, scale: S}`) with S (default 1e-3
# rad) written into a copy of it; runs go to runs/symlog[_S]/seed_<seed>. The probe
# itself ran through a script that patched the same features into train.py (in git:
# experiments/issue12/symlog/symlog.py at commit d88914f); train.py now reads them
# from the config, and evaluate.py from the run's agent.json.
s=$1; scale=${2:-1e-3}
cd "$(dirname "$0")/../../.." && source .venv/bin/activate   # the repository root
export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
folder=runs/symlog; [ "$scale" != 1e-3 ] && folder=runs/symlog_$scale
out=$folder/seed_$s
mkdir -p "$folder"
config=$folder/ppo_symlog.yml
yscale=$(python -c "import sys; print(float(sys.argv[1]))" "$scale") || exit 2   # 1e-3 -> 0.001
sed "s/features: {name: symlog_errors, scale: [0-9.e-]*}/features: {name: symlog_errors, scale: $yscale}/" \
  agents/configs/ppo_symlog.yml > "$config"
grep -q "scale: $yscale}" "$config" || { echo "could not set the scale in $config"; exit 2; }
if [ -f "$out/final_agent/agent.json" ]; then   # finished: kept (remove it to train again)
  echo "$(date -u +%T) kept s=$s S=$scale (finished)"; exit 0
fi
rm -rf "$out"   # an unfinished run starts over (train.py refuses to mix two runs in one folder)
start=$(date +%s)
python train.py --algo ppo --seed "$s" --timesteps 1000000 --config "$config" --out "$out" \
  --no-progress > "$folder/s${s}.log" 2>&1
rc=$?
echo "$(date -u +%T) done s=$s S=$scale rc=$rc wall=$(( $(date +%s) - start ))s"
