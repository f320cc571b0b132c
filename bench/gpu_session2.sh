#!/usr/bin/env bash
# The next device session of issue 34 (about 5 minutes; prepared, not yet run: loans were
# paused): the three one-step equality cases that failed on the GPU in the first session,
# with their sizes; the torch.compile'd step's compile time and throughput; numba-cuda
# again, with np.row_stack restored; one seed of candidate B with the fused env step.
. bench/gpu_setup.sh
{
echo "== equality on the GPU"
TETHER_TEST_DEVICE=cuda timeout 90 python3 -m pytest -q -p no:cacheprovider \
    tests/agents/accel/test_accel_chain.py 2>&1 | grep -E "FAILED|passed|failed|Max (abs|rel)|err_msg|^E +[a-z_\[]+$|Mismatched"
echo "== throughput: eager, torch.compile, numba-cuda"
timeout 220 python3 bench/gpu_throughput.py --device cuda --envs 65536 1048576 --steps 20 \
    --compile --numba-cuda --out $OUT/bench2.json
echo "== one seed of B with the fused step"
timeout 120 python3 train.py gpu --config experiments/issue34/cfg/B.yml --seeds 1 --compile \
    --max-seconds 90 --device cuda --out runs_gpu/single_B_compiled
} 2>&1 | tee $OUT/log2.txt
tar czf $OUT/runs2.tar.gz runs_gpu
