#!/usr/bin/env bash
# Issue 34's targets in one device call (prepared 2026-12-07 without a device; at most
# 575 s). Device time is short (about 15 minutes a session, a fresh machine's start
# included), so this runs what decides the targets first, on the fastest path the CPU
# work has prepared: numba-cuda (the numba env's own step compiled for the GPU), the
# sync-free autoreset, the whole rollout and the whole update as CUDA graphs, and the
# env, rollout and update arithmetic fused by torch.compile. bench/gpu_session3.sh keeps
# the finer checks (each flag alone, part by part) for later sessions.
#   1. one step equals the numba env to 1e-12 on the GPU, both backends (the equality
#      tests' first file; numba-cuda compiles its kernel there, cached for the rest);
#   2. env throughput at 65,536 and 1,048,576 envs: the eager step and 16 sync-free steps
#      per CUDA graph, both backends (target: >= 2e7 env steps/s at >= 65,536 envs);
#   3. one seed of J (configs/gpu_ppo.yml) with all five flags on numba-cuda, 45 s of
#      training (target: ppo_fast's quality in <= 60 s, start-up included); on the torch
#      port instead if that run wrote no agent;
#   4. ten seeds of J in one process, 140 s of training, on the backend that step 3
#      trained (target: the 10-seed row in <= 3 minutes).
# The run folders come back in $OUT/runs4.tar.gz, for `python evaluate.py RUN --no-plots`
# on the development machine (the targets' quality is evaluate.py's).
# Run through the device tool with carry [".whl"] (bench/gpu_setup.sh says how to fill it):
#   bash bench/gpu_session4.sh
. bench/gpu_setup.sh
FLAGS="--cuda-graphs --sync-free --compile --compile-update --compile-rollout"
{
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
python3 -c "import torch, numba; from importlib.metadata import version as v; print('torch', torch.__version__, 'numba', numba.__version__, 'numba-cuda', v('numba-cuda'))"
echo "== 1. one step equal on the GPU (numba-cuda compiles its kernel here, cached on disk)"
for backend in numba-cuda torch; do
  limit=30; [ $backend = numba-cuda ] && limit=90
  TETHER_TEST_DEVICE=cuda TETHER_TEST_BACKEND=$backend timeout $limit python3 -m pytest -q \
      -p no:cacheprovider tests/agents/accel/test_accel_chain.py -k "equals_numba" \
      2>&1 | grep -E "FAILED|passed|failed|Max (abs|rel)|Mismatched|^E .*Error"
done
echo "== 2. throughput, eager and 16 sync-free steps per graph"
timeout 75 python3 bench/gpu_throughput.py --device cuda --envs 65536 1048576 --steps 64 \
    --backend numba-cuda torch --graphed 16 --out $OUT/bench4.json
backend=numba-cuda
for try in numba-cuda torch; do
  echo "== 3. one seed of J, $try, all five flags"
  t=$(date +%s.%N)
  timeout 100 python3 train.py gpu --config configs/gpu_ppo.yml --seeds 1 $FLAGS \
      --backend $try --max-seconds 45 --device cuda --out runs_gpu/one_J_$try
  echo "whole command $(python3 -c "print(round($(date +%s.%N) - $t, 1))") s"
  backend=$try
  [ -f runs_gpu/one_J_$try/seed_0/agent.json ] && break
done
echo "== 4. ten seeds of J, $backend, all five flags"
t=$(date +%s.%N)
timeout 180 python3 train.py gpu --config configs/gpu_ppo.yml --seeds 10 $FLAGS \
    --backend $backend --max-seconds 140 --device cuda --out runs_gpu/ten_J_$backend
echo "whole command $(python3 -c "print(round($(date +%s.%N) - $t, 1))") s"
tar czf $OUT/runs4.tar.gz runs_gpu
} 2>&1 | tee $OUT/log4.txt
