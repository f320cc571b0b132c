# Sourced by the device scripts (bench/gpu_session*.sh): install the carried wheels of
# gymnasium, Farama-Notifications, stable-baselines3 and numba-cuda 0.30.4 (.whl/; the
# device image has torch, numba, an older numba-cuda, the CUDA 13 toolkit with its NVVM,
# safetensors, pyyaml) and put this checkout on the path, agents/ as tether_gym_agents.
# Fill .whl/ here first (Python 3.12 wheels; .whl/ is git-ignored):
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 \
#     --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_24_x86_64 \
#     --platform manylinux2014_x86_64 -d .whl gymnasium==1.4.0 farama-notifications==0.0.6 \
#     stable-baselines3==2.9.2 numba-cuda==0.30.4 rsl-rl-lib==5.5.1 tensordict==0.15.3 \
#     pyvers==0.2.3 GitPython==3.2.1 gitdb==4.0.12 smmap==5.0.3
# (the last six for experiments/issue34/learners.py's rsl_rl runs)
set -u
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl || exit 1
ln -sfn "$PWD/agents" /tmp/site/tether_gym_agents
export PYTHONPATH=/tmp/site:$PWD
[ -d /usr/local/cuda ] && export CUDA_HOME=${CUDA_HOME:-/usr/local/cuda}  # NVVM for numba-cuda
