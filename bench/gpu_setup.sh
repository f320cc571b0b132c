# Sourced by the device scripts (bench/gpu_session*.sh): install the carried wheels of
# gymnasium, Farama-Notifications and stable-baselines3 (.whl/; the device image has
# torch, numba, numba-cuda, safetensors, pyyaml) and put this checkout on the path,
# agents/ as tether_gym_agents.
set -u
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl || exit 1
ln -sfn "$PWD/agents" /tmp/site/tether_gym_agents
export PYTHONPATH=/tmp/site:$PWD
