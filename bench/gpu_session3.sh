#!/usr/bin/env bash
# The next device session of issue 34 (prepared; about 8 minutes; no device was lent to the
# session that wrote it): the numba-cuda backend (the numba env's own step compiled for
# the GPU) against the torch port, on the GPU.
#   1. numba-cuda compiles the step for the device (bench/numba_cuda_ptx.py);
#   2. the equality tests with each backend on the GPU (one step at 1e-12, whole episodes
#      at 1e-9, starts, autoreset), failures with their size;
#   3. env throughput at 65,536 and 1,048,576 envs: torch eager, numba-cuda, and the
#      torch.compile'd core (bench/gpu_throughput.py);
#   4. one seed of candidate B with the numba-cuda backend, 50 s of training; the run
#      folder comes back in $OUT/runs3.tar.gz for `python evaluate.py` here;
#   5. the learner comparison of experiments/issue34/learners.py at B's GPU batch sizes:
#      one seed of the home-made PPO and one of rsl_rl's, 3M env steps each, scored alike.
# Run through the device tool with carry [".whl"] (bench/gpu_setup.sh says how to fill it):
#   bash bench/gpu_session3.sh
. bench/gpu_setup.sh
{
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
python3 -c "import torch, numba, numpy; from importlib.metadata import version as v; print('torch', torch.__version__, 'numba', numba.__version__, 'numpy', numpy.__version__, 'numba-cuda', v('numba-cuda'))"
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
echo "== 4. one seed of B, numba-cuda backend"
t=$(date +%s.%N)
timeout 90 python3 train.py gpu --config experiments/issue34/cfg/B.yml --seeds 1 \
    --backend numba-cuda --max-seconds 50 --device cuda --out runs_gpu/single_B_numba_cuda
echo "whole command $(python3 -c "print(round($(date +%s.%N) - $t, 1))") s"
echo "== 5. home-made PPO against rsl_rl's, B's batch sizes"
for learner in home rsl_rl; do
  timeout 75 python3 experiments/issue34/learners.py --learner $learner --device cuda \
      --config experiments/issue34/cfg/B.yml --timesteps 3000000 --out $OUT/learner_$learner.json \
      | tail -n 1
done
} 2>&1 | tee $OUT/log3.txt
tar czf $OUT/runs3.tar.gz runs_gpu
