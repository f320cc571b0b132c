"""Load a trained stable-baselines3 agent as a policy with the common ``predict``.

A run folder written by ``train.py`` holds ``best_model.zip`` (the evaluation
callback's best) and/or ``final_model.zip``, ``vecnormalize.pkl`` (observation
statistics, when VecNormalize was used) and ``config.yml``. The loaded agent
normalises raw env observations itself, so it runs on the plain environment through
the same evaluation path as the baselines.
"""

from __future__ import annotations

import pickle
import zipfile
from pathlib import Path

import numpy as np

__all__ = ["TrainedAgent", "AgentLoadError", "PRETRAINED_DIR", "pretrained_agents"]

PRETRAINED_DIR = Path(__file__).resolve().parent / "pretrained"
"""Shipped agents: one run folder per algorithm (``ppo``, ``sac``)."""

MODEL_FILES = ("best_model.zip", "final_model.zip", "model.zip")


class AgentLoadError(ValueError):
    """A run folder or model file is missing, corrupt or not a tether_gym agent."""


def _algo_class(name: str):
    from stable_baselines3 import PPO, SAC

    classes = {"ppo": PPO, "sac": SAC}
    try:
        return classes[name.lower()]
    except KeyError:
        raise AgentLoadError(f"unknown algorithm {name!r}; valid: {sorted(classes)}") from None


def _read_algo(run_dir: Path) -> str | None:
    cfg = run_dir / "config.yml"
    if not cfg.is_file():
        return None
    import yaml

    with open(cfg) as fh:
        data = yaml.safe_load(fh) or {}
    return data.get("algo")


class TrainedAgent:
    """A stable-baselines3 model plus its observation normalisation.

    Use :meth:`load`; ``predict`` has stable-baselines3's signature and is
    deterministic by default.
    """

    def __init__(self, model, obs_rms=None, clip_obs: float = 10.0, epsilon: float = 1e-8,
                 name: str = "agent"):
        self.model = model
        self.obs_rms = obs_rms
        self.clip_obs = clip_obs
        self.epsilon = epsilon
        self.name = name

    @classmethod
    def load(cls, path, algo: str | None = None) -> TrainedAgent:
        """Load from a run folder or a model ``.zip`` (with ``vecnormalize.pkl`` beside it).

        Raises
        ------
        AgentLoadError
            If nothing loadable is there or a file is corrupt; the message names the path.
        """
        path = Path(path)
        if path.is_dir():
            run_dir = path
            found = [run_dir / f for f in MODEL_FILES if (run_dir / f).is_file()]
            if not found:
                raise AgentLoadError(f"no model file ({', '.join(MODEL_FILES)}) in {path}")
            model_path = found[0]
        elif path.is_file():
            run_dir = path.parent
            model_path = path
        else:
            raise AgentLoadError(f"agent path {str(path)!r} does not exist")
        algo = algo or _read_algo(run_dir) or _guess_algo(model_path)
        try:
            model = _algo_class(algo).load(model_path, device="cpu")
        except (zipfile.BadZipFile, KeyError, ValueError, EOFError, RuntimeError) as exc:
            raise AgentLoadError(f"cannot load {algo.upper()} model {model_path}: {exc}") from exc
        obs_rms = None
        stats = run_dir / "vecnormalize.pkl"
        if stats.is_file():
            try:
                with open(stats, "rb") as fh:
                    vecnorm = pickle.load(fh)
            except Exception as exc:  # noqa: BLE001 - any unpickling failure is a corrupt file
                raise AgentLoadError(f"corrupt normalisation statistics {stats}: {exc}") from exc
            if not hasattr(vecnorm, "obs_rms"):
                raise AgentLoadError(f"{stats} does not hold VecNormalize statistics")
            obs_rms = vecnorm.obs_rms if vecnorm.norm_obs else None
            return cls(model, obs_rms, vecnorm.clip_obs, vecnorm.epsilon,
                       name=f"{algo}:{run_dir.name}")
        return cls(model, obs_rms, name=f"{algo}:{run_dir.name}")

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        if self.obs_rms is None:
            return obs
        return np.clip((obs - self.obs_rms.mean) / np.sqrt(self.obs_rms.var + self.epsilon),
                       -self.clip_obs, self.clip_obs).astype(np.float32)

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        obs = np.asarray(observation, dtype=np.float32)
        expected = self.model.observation_space.shape
        if obs.shape[-len(expected):] != expected:
            raise ValueError(f"observation of shape {obs.shape} does not fit this agent "
                             f"(trained on observations of shape {expected})")
        return self.model.predict(self.normalize(obs), state=state, episode_start=episode_start,
                                  deterministic=deterministic)

    def __repr__(self) -> str:
        return f"TrainedAgent({self.name})"


def _guess_algo(model_path: Path) -> str:
    try:
        with zipfile.ZipFile(model_path) as zf:
            data = zf.read("data").decode()
    except (zipfile.BadZipFile, KeyError, OSError) as exc:
        raise AgentLoadError(f"{model_path} is not a stable-baselines3 model file: {exc}") from exc
    for algo in ("sac", "ppo"):
        if f"stable_baselines3.{algo}" in data:
            return algo
    raise AgentLoadError(f"cannot tell the algorithm of {model_path}; pass algo='ppo' or 'sac'")


def pretrained_agents() -> dict[str, Path]:
    """The shipped agents that are present: ``{"ppo": path, "sac": path}``."""
    if not PRETRAINED_DIR.is_dir():
        return {}
    return {p.name: p for p in sorted(PRETRAINED_DIR.iterdir())
            if p.is_dir() and any((p / f).is_file() for f in MODEL_FILES)}
