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
#   3. one seed of N (experiments/issue34/cfg/N.yml: J with twice its learning rate and
#      half its steps, the recipe that meets the bar when its schedule ends at 672
#      iterations, as --max-seconds makes it end) with all five flags on numba-cuda, 45 s
#      of training (target: ppo_fast's quality in <= 60 s, start-up included); if that run
#      writes no agent, the next of TRIES below, as time allows: numba-cuda without
#      torch.compile (whose kernels inside a CUDA capture no CPU test can run), then the
#      torch port with the five flags, without torch.compile, and without CUDA graphs
#      (the path measured on 2026-12-04, made sync-free);
#   4. ten seeds of N in one process, up to 140 s of training, on the backend and flags
#      that step 3 trained with (target: the 10-seed row in <= 3 minutes).
# Every step's timeout is cut to what is left of the 575 s, step 4's share kept, so a
# failed try costs its own time only and the call always ends before the tool's limit.
# The run folders come back in $OUT/runs4.tar.gz, for `python evaluate.py RUN --no-plots`
# on the development machine (the targets' quality is evaluate.py's).
# Run through the device tool with carry [".whl"] (bench/gpu_setup.sh says how to fill it):
#   bash bench/gpu_session4.sh
. bench/gpu_setup.sh
FLAGS="--cuda-graphs --sync-free --compile --compile-update --compile-rollout"
CFG=experiments/issue34/cfg/N.yml
TRIES=(  # step 3's tries in turn, backend|flags: the fastest path first
  "numba-cuda|$FLAGS"
  "numba-cuda|--cuda-graphs --sync-free"
  "torch|$FLAGS"
  "torch|--cuda-graphs --sync-free"
  "torch|--sync-free"
)
SECONDS=0
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
try_seconds() {  # a try's timeout: at most 100 s, step 4's 190 s kept back
  local left=$((575 - SECONDS - 190)); echo $((left < 100 ? left : 100))
}
backend=""; flags=""
i=0
for try in "${TRIES[@]}"; do
  b=${try%%|*}; f=${try#*|}; limit=$(try_seconds); i=$((i + 1))
  [ "$limit" -lt 50 ] && { echo "== 3. no time left for try $i, $b $f ($limit s)"; break; }
  name=one_N_try${i}_$b
  echo "== 3. try $i: one seed of N, $b, $f (timeout $limit s)"
  t=$(date +%s.%N)
  timeout $limit python3 train.py gpu --config $CFG --seeds 1 $f \
      --backend $b --max-seconds 45 --device cuda --out runs_gpu/$name
  echo "whole command $(python3 -c "print(round($(date +%s.%N) - $t, 1))") s"
  if [ -f runs_gpu/$name/seed_0/agent.json ]; then backend=$b; flags=$f; break; fi
done
if [ -n "$backend" ]; then
  limit=$((575 - SECONDS - 10)); [ $limit -gt 180 ] && limit=180
  train=$((limit - 40)); [ $train -gt 140 ] && train=140
  echo "== 4. ten seeds of N, $backend, $flags ($train s of training, timeout $limit s)"
  t=$(date +%s.%N)
  timeout $limit python3 train.py gpu --config $CFG --seeds 10 $flags \
      --backend $backend --max-seconds $train --device cuda --out runs_gpu/ten_N_$backend
  echo "whole command $(python3 -c "print(round($(date +%s.%N) - $t, 1))") s"
else
  echo "== 4. skipped: no try of step 3 wrote an agent"
fi
tar czf $OUT/runs4.tar.gz runs_gpu
} 2>&1 | tee $OUT/log4.txt
