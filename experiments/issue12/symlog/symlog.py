"""Probe: PPO whose network also sees the tracking errors on a logarithmic scale.

The policy's input gets, beside the env's observation, symlog(e_i / S) and
symlog(e_i' / S) with symlog(x) = sign(x) ln(1 + |x|) and S = 1e-3 rad, so that
errors of 1e-3 to 1e-2 rad, compressed to about 0.1 of a unit by VecNormalize in
the plain observation (the error's training std is about 0.036 rad), span about
one unit. The env is unchanged: the features are appended by a VecEnvWrapper below
VecNormalize in training, and by the same function in front of the agent at
evaluation, so `train.py` and `evaluate.py` run in-process with two patches.

(The probe ran with its own copy of the features and of the wrapper; the same
operations are now ``tether_gym_agents.common.features`` and ``FeatureVecEnv``, used here,
which ``configs/ppo_symlog.yml`` turns on without patches: ``features: {name:
symlog_errors, scale: 0.01}``.)

    python experiments/issue12/symlog/symlog.py train --seed 0 --timesteps 1000000 --out R
    python experiments/issue12/symlog/symlog.py evaluate R [evaluate.py arguments]

SYMLOG_SCALE=1e-2 sets S (default 1e-3); evaluate with the S the run was trained with.
"""

from __future__ import annotations

import os
import sys

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from tether_gym_agents import evaluation, trained, training  # noqa: E402
from tether_gym_agents.common.features import FeatureSpec, add_features  # noqa: E402
from tether_gym_agents.training.vec_env import FeatureVecEnv  # noqa: E402

SCALE = float(os.environ.get("SYMLOG_SCALE", "1e-3"))
"""S of symlog(e / S) [rad], [rad/rad] for e' (environment variable SYMLOG_SCALE)."""


SPEC = FeatureSpec("symlog_errors", SCALE)


def _patch_training() -> None:
    make = training._make_venv

    def make_venv(*args, **kwargs):
        return FeatureVecEnv(make(*args, **kwargs), SPEC)

    training._make_venv = make_venv


def _patch_agent() -> None:
    predict = trained.TrainedAgent.predict

    def patched(self, observation, state=None, episode_start=None, deterministic=True):
        obs = np.asarray(observation, dtype=np.float32)
        want = self.model.observation_space.shape[0]
        if obs.shape[-1] != want:
            n = (want - obs.shape[-1]) // 2
            obs = add_features(SPEC, obs, n)
        return predict(self, obs, state, episode_start, deterministic)

    trained.TrainedAgent.predict = patched


def main(argv: list[str]) -> int:
    """``train ...`` (train.py's arguments) or ``evaluate ...`` (evaluate.py's)."""
    what, rest = argv[0], argv[1:]
    if what == "train":
        _patch_training()
        return training.main(["--algo", "ppo", "--no-progress", *rest])
    if what == "evaluate":
        _patch_agent()
        return evaluation.main(rest)
    raise SystemExit(f"unknown command {what!r}: train or evaluate")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
