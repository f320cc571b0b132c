#!/bin/bash
# One training seed of the shipped rows distill_bc and distill_ppo (issue 36;
# docs/distillation.md, "The shipped rows"):
#   1. behaviour cloning of mpc on set A of the shared dataset, symlog error features of
#      scale 1e-4 rad (bc.sh's a_symlog fit, with this seed) -> runs/row36/bc/seed_SEED,
#      exported to agents/pretrained/distill_bc/seed_SEED;
#   2. PPO fine-tuning of that student (agents/configs/distill_ppo.yml, whose
#      init_policy is distill_bc/seed_{seed}) -> runs/distill_ppo/seed_SEED: 1M env
#      steps, then resumed to 2M (the training evaluations' return was still rising at 1M).
# Needs runs/distill_data/ from experiments/issue36/make_data.sh. Re-running skips what
# is finished and resumes an interrupted fine-tune.
# usage: experiments/issue36/distill_row.sh SEED
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
seed=$1
bc=runs/row36/bc/seed_$seed
ft=runs/distill_ppo/seed_$seed
source experiments/issue36/set_a.sh   # parts A | B | AB
mapfile -t data < <(parts A)
if [ ! -f "$bc/agent.json" ]; then
  rm -rf "$bc"   # an unfinished fit starts over (train.py distill has no resume)
  python train.py distill --data "${data[@]}" --iterations 0 --epochs 40 --batch-size 2048 \
    --check-episodes 0 --symlog-scale 1e-4 --seed "$seed" --out "$bc"
fi
if [ ! -f "agents/pretrained/distill_bc/seed_$seed/agent.json" ]; then
  python -m tether_gym_agents.files export "$bc" "agents/pretrained/distill_bc/seed_$seed"
fi
ft_args=(--config configs/distill_ppo.yml --seed "$seed" --out "$ft" --eval-episodes 20
         --no-progress)
if [ ! -f "$ft/final_model.zip" ]; then   # the first call (resumed if it was interrupted)
  resume=()
  [ -d "$ft/checkpoints" ] && resume=(--resume)
  python train.py "${ft_args[@]}" "${resume[@]}"
fi
steps=$(python -c "import json; print(json.load(open('$ft/train_info.json'))['num_timesteps'])")
if ((steps < 2000000)); then   # the second call, to 2M env steps
  python train.py "${ft_args[@]}" --resume --timesteps $((2000000 - steps))
fi
