"""Load a trained agent as a policy with the common ``predict``.

An agent is a folder in the safe format of :mod:`tether_gym_agents.files.safe_format`
(``agent.json`` + ``policy.safetensors``: tensors and plain data only, so loading never runs
code). ``TrainedAgent.load`` accepts such a folder, a run folder written by
``train.py`` (its best agent sits at the top, the final one in ``final_agent/``,
which is loaded when there is no best yet) or the ``agent.json``
file itself. stable-baselines3's pickled files (``*.zip``, ``vecnormalize.pkl``) are
refused unless ``allow_pickle=True`` is passed (with a warning). The loaded agent
normalises raw env observations itself, so it runs on the plain environment through
the same evaluation path as the baselines.
"""

from __future__ import annotations

import errno
import json
import os
import stat
from pathlib import Path

import numpy as np

from ..common.features import FeatureSpec, add_features
from .folder_paths import FolderFileError, file_inside, folder_inside
from .mlp import NumpyMLP
from .pickled import is_pickled_run, load_pickled_run, run_features, run_hybrid
from .run_folder import CONFIG_FILE, FINAL_AGENT_DIR, read_config, seed_runs
from .safe_format import (
    AGENT_FILE,
    WEIGHTS_FILE,
    AgentLoadError,
    ObsNormalization,
    checked_file,
    is_unit,
    load_agent,
    normalization_of,
)

__all__ = ["TrainedAgent", "AgentLoadError", "PRETRAINED_DIR", "pretrained_agents",
           "RUN_AGENT_DIRS", "find_unit", "hybrid_of", "refuse_special_file"]

PRETRAINED_DIR = Path(__file__).resolve().parents[1] / "pretrained"
"""Shipped agents: one folder (or folder of seed runs) per name (``ppo``, ...)."""

RUN_AGENT_DIRS = (FINAL_AGENT_DIR,)
"""Safe agent folders inside a ``train.py`` run folder, in the order they are tried."""


def refuse_special_file(path) -> None:
    """Refuse ``path`` when it exists but is neither a regular file nor a folder.

    A FIFO, a device such as ``/dev/zero`` or a socket (or a link to one) is never opened:
    reading it would hang or never end.

    Raises
    ------
    AgentLoadError
        ``"<path> is not a regular file or an agent folder (...)"``, or the path is
        longer than the system allows.
    """
    try:
        mode = os.stat(path).st_mode
    except OSError as exc:
        if exc.errno == errno.ENAMETOOLONG:
            text = str(path)
            raise AgentLoadError(f"agent path {text[:60]!r}... ({len(text)} characters): "
                                 f"{exc.strerror}") from None
        return  # missing: the caller says what it expected there
    except ValueError:
        return  # an invalid name (a NUL byte): no such file either
    if not (stat.S_ISDIR(mode) or stat.S_ISREG(mode)):
        raise AgentLoadError(f"{path} is not a regular file or an agent folder (a FIFO, "
                             "device or socket is never read)")


def find_unit(path) -> Path | None:
    """The safe agent folder that ``path`` designates, or None when there is none.

    Raises
    ------
    AgentLoadError
        When a run folder's ``final_agent/`` is a symlink leading outside the run folder
        (evaluating it would evaluate another agent than the run's), or an
        ``agent.json`` there is not a regular file inside its folder (a FIFO, a link out).
    """
    path = Path(path)
    if path.is_file():
        if path.name in (AGENT_FILE, WEIGHTS_FILE):
            return path.parent
        return None
    _check_agent_file(path)
    if is_unit(path):
        return path
    for sub in RUN_AGENT_DIRS:
        if (path / sub).is_symlink():
            try:
                folder_inside(path, path / sub)
            except FolderFileError as exc:
                raise AgentLoadError(str(exc)) from None
        _check_agent_file(path / sub)
        if is_unit(path / sub):
            return path / sub
    return None


def _check_agent_file(folder: Path) -> None:
    """Refuse an ``agent.json`` that is there but not a regular file inside ``folder``.

    (A FIFO or a link to ``/dev/zero`` named ``agent.json`` is named as such, not taken
    for a folder without an agent.)
    """
    meta = folder / AGENT_FILE
    if meta.is_symlink() or (meta.exists() and not meta.is_file()):
        checked_file(folder, meta)


def hybrid_of(path) -> dict | None:
    """The recorded ``hybrid`` entry of the agent at ``path``, read without loading it.

    Reads ``agent.json`` (or, for a run folder of pickled files only, its
    ``config.yml``) as plain data; None when there is no entry or nothing readable
    (:meth:`TrainedAgent.load` then reports what is wrong).
    """
    path = Path(path)
    unit = find_unit(path)
    try:
        if unit is not None:
            meta = json.loads(file_inside(unit, unit / AGENT_FILE).read_text())
            return meta.get("hybrid") if isinstance(meta, dict) else None
        run = path if path.is_dir() else path.parent
        if (run / CONFIG_FILE).is_file():
            data = read_config(run)  # its errors are ValueErrors: None below
            return run_hybrid(data) if isinstance(data, dict) else None
    except (OSError, UnicodeDecodeError, ValueError, AttributeError, RecursionError):
        return None
    return None


class TrainedAgent:
    """A stable-baselines3 policy plus its observation normalisation.

    Use :meth:`load`; ``predict`` has stable-baselines3's signature and is
    deterministic by default.

    Attributes
    ----------
    model : stable_baselines3 BasePolicy
        The policy (``model.observation_space``, ``model.predict``).
    norm : ObsNormalization or None
        The observation statistics it was trained with (None: not normalised).
    algo : str
        A name of :data:`~tether_gym_agents.common.algorithms.ALGORITHMS` (``"ppo"``,
        ``"td3"``, ...), as recorded in the agent's files.
    env_id, env_kwargs : str or None, dict
        The environment the agent was trained on (as recorded).
    path : Path or None
        The folder it was loaded from.
    hybrid : dict or None
        ``{"base", "scale", "filter"}`` when the policy is the residual of a hybrid
        (it then acts only through :class:`~tether_gym_agents.hybrids.policies.ResidualPolicy`),
        None for a policy that acts alone.
    features : FeatureSpec or None
        The input features the policy appends to each observation before it is
        normalised (:mod:`tether_gym_agents.common.features`); None: the observation alone.
    """

    def __init__(self, model, norm: ObsNormalization | None = None, name: str = "agent",
                 algo: str | None = None, env_id: str | None = None,
                 env_kwargs: dict | None = None, path: Path | None = None,
                 hybrid: dict | None = None, features: dict | None = None):
        self.model = model
        self.norm = norm
        self.name = name
        self.algo = algo
        self.env_id = env_id
        self.env_kwargs = dict(env_kwargs or {})
        self.path = path
        self.hybrid = dict(hybrid) if hybrid is not None else None
        self.features = (FeatureSpec.from_dict(features, "features") if features is not None
                         else None)
        model.set_training_mode(False)  # once here, not on every predict
        self.mlp = NumpyMLP.from_policy(model)
        """The batch-invariant float64 forward pass of the deterministic action
        (:mod:`tether_gym_agents.files.mlp`), None when the network is not a plain MLP."""

    @property
    def batch_invariant(self) -> bool:
        """True when a deterministic action does not depend on the rest of the batch."""
        return self.mlp is not None

    @property
    def observation_space(self):
        """The observation space of the policy's network (with its :attr:`features`)."""
        return self.model.observation_space

    @property
    def action_space(self):
        """The action space the agent was trained on."""
        return self.model.action_space

    @classmethod
    def load(cls, path, algo: str | None = None, allow_pickle: bool = False) -> TrainedAgent:
        """Load an agent folder, a run folder or ``agent.json``; pickles only on opt-in.

        Parameters
        ----------
        path : path-like
            Safe agent folder (``agent.json`` + ``policy.safetensors``), a ``train.py`` run
            folder (its best agent, else ``final_agent/``) or the ``agent.json`` file.
            With ``allow_pickle=True`` also a run folder or model ``.zip`` holding only
            stable-baselines3's pickled files, of ``train.py`` or of rl-baselines3-zoo
            (``logs/ppo/tether_gym-TetherLibration-v1_1``; :mod:`.zoo_folder`).
        algo : str or None
            Only for pickled run folders whose ``config.yml`` lacks the algorithm.
        allow_pickle : bool
            Load stable-baselines3's pickled ``.zip`` / ``vecnormalize.pkl`` (they can run
            code when loaded; a warning is issued). Safe files are always preferred.

        Raises
        ------
        AgentLoadError
            If nothing loadable is there, ``path`` is not a regular file or a folder (a
            FIFO, ``/dev/zero``), a piece of the agent is missing (named), a file is
            corrupt, or only pickled files are there and ``allow_pickle`` is False.
        """
        path = Path(path)
        refuse_special_file(path)
        if not path.exists():
            raise AgentLoadError(f"agent path {str(path)!r} does not exist")
        unit = find_unit(path)
        if unit is not None:
            policy, meta = load_agent(unit)
            label = (path.parent if path.is_file() else path).name
            return cls(policy, normalization_of(meta), name=f"{meta['algo']}:{label}",
                       algo=meta["algo"], env_id=meta["env"].get("id"),
                       env_kwargs=meta["env"].get("kwargs"),
                       path=unit, hybrid=meta["hybrid"], features=meta["features"])
        if path.is_file() and path.suffix not in (".zip", ".pkl"):
            raise AgentLoadError(f"{path} is not an agent file: give an agent folder "
                                 f"({AGENT_FILE} + {WEIGHTS_FILE}) or a run folder")
        if path.is_dir() and not is_pickled_run(path):
            raise AgentLoadError(f"no agent in {path}: no {AGENT_FILE} (nor "
                                 f"{'/, '.join(RUN_AGENT_DIRS)}/ holding one), no pickled "
                                 "model of train.py or rl_zoo3")
        run = load_pickled_run(path, allow_pickle=allow_pickle, algo=algo)
        cfg = run.config
        return cls(run.model.policy, run.norm, name=f"{run.algo}:{run.run_dir.name}",
                   algo=run.algo, env_id=cfg.get("env_id"), env_kwargs=cfg.get("env_kwargs"),
                   path=run.run_dir, hybrid=run_hybrid(cfg), features=run_features(cfg))

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        """Observations as the policy saw them in training (VecNormalize's formula)."""
        return obs if self.norm is None else self.norm.apply(obs)

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """stable-baselines3's ``predict`` for one observation or a batch: (action, state).

        The same computation as ``BasePolicy.predict``, after appending the agent's
        :attr:`features` (if any): normalise, forward pass, unscale a squashed action or
        clip it to the box. Deterministic actions of a plain MLP come
        from the float64 NumPy forward pass (:attr:`mlp`), so each row of a batch is
        bitwise what it would be alone; otherwise torch's forward pass runs without
        SB3's per-call set-up. An observation holding NaN or inf raises ``ValueError``
        (it would act NaN).
        """
        import torch

        with np.errstate(over="ignore"):  # beyond float32's range: inf, refused below
            obs = np.asarray(observation, dtype=np.float32)
        if not np.isfinite(obs).all():  # an env never returns one; NaN would act NaN
            raise ValueError("observation holds NaN or inf (or values beyond float32's "
                             "range); allowed: finite numbers, as the env returns them")
        if self.features is not None:
            obs = add_features(self.features, obs, self.model.action_space.shape[0])
        expected = self.model.observation_space.shape
        if obs.shape[-len(expected):] != expected or obs.ndim > len(expected) + 1:
            raise ValueError(f"observation of shape {obs.shape} does not fit this agent "
                             f"(trained on observations of shape {expected}"
                             + (", its features included)" if self.features else ")"))
        single = obs.ndim == len(expected)
        batch = self.normalize(obs).reshape((-1, *expected))
        if deterministic and self.mlp is not None:
            actions = self.mlp(batch)
            return (actions[0] if single else actions), state
        with torch.no_grad():
            actions = self.model._predict(torch.as_tensor(batch), deterministic=deterministic)
        space = self.model.action_space
        actions = actions.cpu().numpy().reshape((-1, *space.shape))
        if self.model.squash_output:
            actions = self.model.unscale_action(actions)
        else:
            actions = np.clip(actions, space.low, space.high)
        return (actions[0] if single else actions), state

    def __repr__(self) -> str:
        return f"TrainedAgent({self.name})"


def pretrained_agents() -> dict[str, Path]:
    """The shipped agents that are present: ``{name: path}`` (``"ppo"``, ``"sac"``, ...).

    An agent folder, or a folder of ``seed_K`` agent folders (one policy trained over
    several seeds).
    """
    if not PRETRAINED_DIR.is_dir():
        return {}
    return {p.name: p for p in sorted(PRETRAINED_DIR.iterdir())
            if p.is_dir() and (find_unit(p) is not None
                               or any(find_unit(q) is not None for q in seed_runs(p)))}
