#!/usr/bin/env bash
# The next device session of issue 34 (prepared; about 11 minutes; no device was lent to
# the sessions that wrote it): the numba-cuda backend (the numba env's own step compiled for
# the GPU) against the torch port, on the GPU.
#   1. numba-cuda compiles the step for the device (bench/numba_cuda_ptx.py);
#   2. the equality tests with each backend on the GPU (one step at 1e-12, whole episodes
#      at 1e-9, starts, autoreset), failures with their size;
#   3. env throughput at 65,536 and 1,048,576 envs: torch eager, numba-cuda, and the
#      torch.compile'd core (bench/gpu_throughput.py);
#   4. the CUDA graphs of the learner's pieces and of the env's step and resets
#      (agents/accel/graphs.py, written 2026-12-07 without a device): their tests on the
#      GPU, where CUDA's capture runs;
#   5. one seed of J (cfg/J.yml: ppo_fast's 64-step rollouts, 80 gradient steps and 1,343
#      iterations with twice its envs and minibatch; on the CPU it tracks at half
#      ppo_fast's error in 11M env steps: experiments/issue34/README.md) on the
#      numba-cuda backend, 40 s of training (the learning rate falls to 0 at the time
#      budget), eager, then the same with --cuda-graphs;
#   5b. an iteration of J with --cuda-graphs timed part by part (bench/accel_iteration.py:
#      the policy's half with the env's first part, the kernel, the autoreset, the
#      learner's half, the advantages, the updates), each part between device syncs;
#   6. ten seeds of J in one process, 150 s, with --cuda-graphs if step 5 wrote its
#      graphed run (else eager), on the numba-cuda backend if step 5 wrote its eager run,
#      else on the torch backend: the GPU-trained candidate for the `ppo_accel` row,
#      which ships J trained on the CPU (docs/gpu.md).
#   Steps 5-6 time an iteration (128 x 64 = 8,192 env steps per seed): env steps per
#   seed / 8,192 / wall time, from the checkpoint lines of the logs. bench/accel_ops.py
#   counts about 34k torch operations per eager iteration on the numba-cuda backend (with
#   CUDA's fused Adam), and about 470 launches from the host with --cuda-graphs (the
#   env's step, resets and whole update graphed too); at the eager torch step's rate
#   on the H200 of 2026-12-04 (about 15 us per operation) that is about 0.5 s and
#   0.007 s, the latter plus the replayed kernels' own time on the GPU, which nothing
#   has measured and which now decides: 40 s buy about 80 of J's 1,343 iterations
#   eager. The time per iteration with and without graphs, not the scores, is what
#   these runs can tell (bench/README.md).
#   The run folders come back in $OUT/runs3.tar.gz for `python evaluate.py` here. The
#   learner comparison (experiments/issue34/learners.py --device cuda --config
#   configs/gpu_ppo.yml) is left for a session with time to spare.
#   7. (a third call, if device time is left) the learner and the env's torch parts fused
#      by torch.compile (--compile-update, --compile-rollout and --compile on the
#      numba-cuda backend, written 2026-12-07 without a device; on the CPU 367 -> 27
#      kernels per minibatch step, 218 -> 35 per rollout step): their kernels and time
#      on the GPU, eager against fused (bench/accel_update.py and bench/accel_rollout.py
#      --env numba-cuda, 10 seeds), an iteration of J with the three flags timed part by
#      part, without and with --cuda-graphs, and with --sync-free too (the autoreset
#      without host syncs, 2026-12-07), and one seed of J with all five for 40 s.
#   8. (another call, if device time is left) the whole rollout as one graph
#      (--cuda-graphs --sync-free, written 2026-12-07 without a device; the numba-cuda
#      kernel now launched on torch's current stream so that CUDA's capture records it):
#      the GPU tests of graphed training with each backend, the env's throughput with
#      16 sync-free steps per graph (bench/gpu_throughput.py --graphed), an iteration of J timed
#      with per-step graphs (the default autoreset) and as one graph on numba-cuda, as one
#      graph on the torch port, eager and fused (its resets compiled since 2026-12-07),
#      and one seed of J for 40 s as one graph on numba-cuda.
# Run through the device tool with carry [".whl"] (bench/gpu_setup.sh says how to fill it),
# as separate calls, each under the tool's 10 minutes even at every timeout:
#   bash bench/gpu_session3.sh check       # steps 1-3 (at most 500 s; about 4 minutes)
#   bash bench/gpu_session3.sh train       # steps 4-6 (at most 550 s; about 6 minutes)
#   bash bench/gpu_session3.sh fused       # step 7 (at most 570 s; about 5 minutes)
#   bash bench/gpu_session3.sh whole       # step 8 (at most 570 s; about 5 minutes)
. bench/gpu_setup.sh
PART=${1:-check}
{
if [ "$PART" = check ]; then
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
nproc; python3 -c "import torch, numba, numpy; from importlib.metadata import version as v; print('torch', torch.__version__, 'numba', numba.__version__, 'numpy', numpy.__version__, 'numba-cuda', v('numba-cuda'))"
echo "== 1. numba-cuda compiles the step"
timeout 60 python3 bench/numba_cuda_ptx.py
for backend in torch numba-cuda; do
  echo "== 2. equality on the GPU, backend $backend"
  TETHER_TEST_DEVICE=cuda TETHER_TEST_BACKEND=$backend timeout 120 python3 -m pytest -q \
      -p no:cacheprovider tests/agents/accel/test_accel_chain.py \
      tests/agents/accel/test_accel_vec_env.py -k "equal_numba or equals_numba or autoreset" \
      2>&1 | grep -E "FAILED|passed|failed|Max (abs|rel)|Mismatched|^E .*Error"
done
echo "== 3. throughput"
timeout 200 python3 bench/gpu_throughput.py --device cuda --envs 65536 1048576 --steps 20 \
    --backend torch numba-cuda --compile --out $OUT/bench3.json
fi
if [ "$PART" = train ]; then
echo "== 4. the CUDA graphs of the learner's pieces"
timeout 150 python3 -m pytest -q -p no:cacheprovider tests/agents/accel/test_accel_graphs.py \
    2>&1 | grep -E "FAILED|passed|failed|skipped|^E .*Error"
for graphs in "" --cuda-graphs; do
  echo "== 5. one seed of J, numba-cuda backend ${graphs:-eager}"
  t=$(date +%s.%N)
  timeout 70 python3 train.py gpu --config configs/gpu_ppo.yml --seeds 1 $graphs \
      --backend numba-cuda --max-seconds 40 --device cuda \
      --out runs_gpu/single_J_numba_cuda${graphs:+_graphs}
  echo "whole command $(python3 -c "print(round($(date +%s.%N) - $t, 1))") s"
done
echo "== 5b. where a graphed iteration of J spends its time"
timeout 60 python3 bench/accel_iteration.py --device cuda --backend numba-cuda --cuda-graphs \
    --iterations 12 | tee $OUT/iteration3.json
backend=torch
[ -f runs_gpu/single_J_numba_cuda/seed_0/agent.json ] && backend=numba-cuda
graphs=
[ -f runs_gpu/single_J_numba_cuda_graphs/seed_0/agent.json ] && graphs=--cuda-graphs
echo "== 6. ten seeds of J, backend $backend ${graphs:-eager}"
t=$(date +%s.%N)
timeout 190 python3 train.py gpu --config configs/gpu_ppo.yml --seeds 10 $graphs \
    --backend $backend --max-seconds 150 --device cuda --out runs_gpu/ten_J
echo "whole command $(python3 -c "print(round($(date +%s.%N) - $t, 1))") s"
tar czf $OUT/runs3.tar.gz runs_gpu
fi
if [ "$PART" = fused ]; then
echo "== 7. the learner fused (--compile-update --compile-rollout --compile)"
timeout 100 python3 bench/accel_update.py --device cuda --seeds 10 | tee $OUT/update3.json
timeout 80 python3 bench/accel_rollout.py --device cuda --seeds 10 --env numba-cuda \
    | tee $OUT/rollout3.json
# the flags without graphs first: their CUDA capture (a compiled function's kernels inside
# torch.cuda.graph) is the one combination the CPU tests cannot reach
timeout 90 python3 bench/accel_iteration.py --device cuda --backend numba-cuda \
    --compile-update --compile-rollout --compile --iterations 12 | tee $OUT/iteration3_compiled.json
timeout 90 python3 bench/accel_iteration.py --device cuda --backend numba-cuda --cuda-graphs \
    --compile-update --compile-rollout --compile --iterations 12 | tee $OUT/iteration3_fused.json
# and without the autoreset's host syncs (--sync-free: one reset attempt every step)
timeout 90 python3 bench/accel_iteration.py --device cuda --backend numba-cuda --cuda-graphs \
    --compile-update --compile-rollout --compile --sync-free --iterations 12 \
    | tee $OUT/iteration3_sync_free.json
t=$(date +%s.%N)
timeout 120 python3 train.py gpu --config configs/gpu_ppo.yml --seeds 1 --cuda-graphs \
    --compile-update --compile-rollout --compile --sync-free --backend numba-cuda \
    --max-seconds 40 --device cuda \
    --out runs_gpu/single_J_fused
echo "whole command $(python3 -c "print(round($(date +%s.%N) - $t, 1))") s"
tar czf $OUT/runs3_fused.tar.gz runs_gpu/single_J_fused
fi
if [ "$PART" = whole ]; then
echo "== 8. the whole rollout as one graph (--cuda-graphs --sync-free)"
timeout 120 python3 -m pytest -q -p no:cacheprovider tests/agents/accel/test_accel_graphs.py \
    -k runs_on_a_gpu 2>&1 | grep -E "FAILED|passed|failed|skipped|^E .*Error"
# the env alone: 16 sync-free steps per graph at the issue's batch sizes
timeout 90 python3 bench/gpu_throughput.py --device cuda --envs 65536 1048576 --steps 64 \
    --backend torch numba-cuda --graphed 16 --out $OUT/bench3_graphed.json
# an iteration of J: numba-cuda with per-step graphs, then as one graph; the torch port
# as one graph, eager and with the three compile flags (its resets fused since 2026-12-07)
for flags in "--backend numba-cuda" "--backend numba-cuda --sync-free" \
    "--backend torch --sync-free"; do
  timeout 50 python3 bench/accel_iteration.py --device cuda --cuda-graphs $flags \
      --iterations 12 | tee -a $OUT/iteration3_whole.json
done
timeout 110 python3 bench/accel_iteration.py --device cuda --cuda-graphs --backend torch \
    --sync-free --compile --compile-update --compile-rollout --iterations 12 \
    | tee -a $OUT/iteration3_whole.json
t=$(date +%s.%N)
timeout 100 python3 train.py gpu --config configs/gpu_ppo.yml --seeds 1 --cuda-graphs \
    --sync-free --backend numba-cuda --max-seconds 40 --device cuda \
    --out runs_gpu/single_J_whole
echo "whole command $(python3 -c "print(round($(date +%s.%N) - $t, 1))") s"
tar czf $OUT/runs3_whole.tar.gz runs_gpu/single_J_whole
fi
} 2>&1 | tee $OUT/log3_$PART.txt
