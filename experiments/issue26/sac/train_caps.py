"""train.py with SAC replaced by CapsSAC (caps.py beside this file): the probe launcher.

The package is not patched; this script swaps the algorithm class in for one call:
``python experiments/issue26/sac/train_caps.py --algo sac --config
experiments/issue26/sac/cfg/capsA0g995.yml --seed 0 --timesteps 300000 --out
runs/sacprobe/capsA0g995_s0`` (the ``caps_*`` keys of a config reach CapsSAC).
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from caps import CapsSAC  # noqa: E402

from tether_gym_agents.training import config, run  # noqa: E402

_original = config.algo_class


def algo_class(algo):
    return CapsSAC if algo == "sac" else _original(algo)


config.algo_class = algo_class
run.algo_class = algo_class

from tether_gym_agents.cli.train import main  # noqa: E402

sys.exit(main())
