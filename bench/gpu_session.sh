#!/usr/bin/env bash
# The one device session of issue 34, as run on the lent GPU machine (through the device
# tool: this repository's root is the working directory, $OUT comes back). About 8 minutes:
#   1. the torch step equal to the numba step on the GPU (tests/agents/accel/test_accel_chain.py);
#   2. env throughput at 4096 .. 1M envs (bench/gpu_throughput.py; as run that day it also
#      passed --numba-cuda, a probe that compiled kernels.advance_one into a CUDA kernel and
#      failed inside numba-cuda (docs/gpu.md); the probe is gone: bench/numba_cuda_ptx.py
#      compiles the step without a GPU, and --backend numba-cuda times it);
#   3. one seed of each candidate recipe (experiments/issue34/cfg/{A,B,C}.yml), 45 s each;
#   4. ten seeds in one process of the candidate whose final deterministic episodes on the
#      training distribution (not a benchmark suite) return the most, 140 s;
#   5. every run folder packed into $OUT/runs.tar.gz, for `python evaluate.py` here.
# Needs the wheels that bench/gpu_setup.sh installs, in .whl/.
. bench/gpu_setup.sh
LOG=$OUT/log.txt
stamp() { date +%s.%N; }
{
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
nproc; python3 -c "import torch, numba, gymnasium; print('torch', torch.__version__, 'numba', numba.__version__, 'gymnasium', gymnasium.__version__)"
echo "== 1. equality on the GPU"
TETHER_TEST_DEVICE=cuda timeout 90 python3 -m pytest -q -p no:cacheprovider tests/agents/accel/test_accel_chain.py 2>&1 | tail -3
echo "== 2. throughput"
timeout 100 python3 bench/gpu_throughput.py --device cuda --envs 4096 65536 262144 1048576 \
    --steps 10 --out $OUT/bench.json
echo "== 3. one seed per candidate"
for c in A B C; do
  t=$(stamp)
  timeout 70 python3 train.py gpu --config experiments/issue34/cfg/$c.yml --seeds 1 --seed 0 \
      --max-seconds 45 --device cuda --out runs_gpu/single_$c
  echo "candidate $c: whole command $(python3 -c "print(round($(stamp) - $t, 1))") s"
done
best=$(python3 - <<'PY'
import json
score = {}
for c in "ABC":
    try:
        info = json.load(open(f"runs_gpu/single_{c}/seed_0/train_info.json"))
        score[c] = info["final_training_distribution"]["mean_return"]
    except (OSError, KeyError):
        pass
print(max(score, key=score.get) if score else "C")
PY
)
echo "== 4. ten seeds of candidate $best"
t=$(stamp)
timeout 170 python3 train.py gpu --config experiments/issue34/cfg/$best.yml --seeds 10 --seed 0 \
    --max-seconds 140 --device cuda --out runs_gpu/ten_$best
echo "ten seeds: whole command $(python3 -c "print(round($(stamp) - $t, 1))") s"
} 2>&1 | tee $LOG
tar czf $OUT/runs.tar.gz runs_gpu
ls -la $OUT
