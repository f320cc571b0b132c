"""The native vector environment of ``tether_gym/TetherLibration-v1``.

``gym.make_vec("tether_gym/TetherLibration-v1", num_envs=n, **kwargs)`` builds a
:class:`TetherLibrationVectorEnv`: one :class:`~tether_gym.envs.batch.ChainBatch` of n
rows advanced by the same compiled step as the single env, so sub-env i produces
exactly the trajectory of a :class:`~tether_gym.envs.TetherLibrationEnv` seeded and
driven the same way.
"""

from __future__ import annotations

import time
from itertools import chain
from typing import Any

import numpy as np
from gymnasium import logger
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..params import check_count
from ..physics import TetherChain
from .batch import ChainBatch, check_options
from .config import EnvConfig
from .layout import INFO_KEYS
from .tether_libration import action_space, eccentricity_of, observation_space
from .threads import ThreadPolicy

__all__ = ["TetherLibrationVectorEnv", "MAX_NUM_ENVS", "check_num_envs"]

_PAIRED_KEYS = tuple(chain.from_iterable((key, "_" + key) for key in INFO_KEYS))
"""The vector infos' keys in gymnasium's order: each key, then its mask ``_key``."""


MAX_NUM_ENVS = 1 << 22
"""The most sub-envs one vector env holds (4,194,304): a sub-env keeps about 650 B of
arrays here (2.7 GB at the cap; 10^7 sub-envs measured 6.5 GB resident), the torch
twin's rollouts more; more envs at once: several vector envs, or several processes."""


def check_num_envs(num_envs) -> int:
    """``num_envs`` as an int in [1, :data:`MAX_NUM_ENVS`]; TypeError or ValueError else."""
    return check_count("num_envs", num_envs, 1, MAX_NUM_ENVS,
                       "one vector env's sub-envs; more at once: several vector envs")


def _check_seeds(seed, num_envs: int) -> list[int | None]:
    """gymnasium's SyncVectorEnv convention: None, an int s (env i gets s + i) or a list."""
    if seed is None:
        return [None] * num_envs
    if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
        return [int(seed) + i for i in range(num_envs)]
    if isinstance(seed, (list, tuple, np.ndarray)):
        seeds = list(seed)
        if len(seeds) != num_envs:
            raise ValueError(f"seed={seed!r} has {len(seeds)} entries; a list of seeds needs "
                             f"one per env (num_envs={num_envs})")
        for s in seeds:
            if s is not None and (isinstance(s, bool) or not isinstance(s, (int, np.integer))):
                raise TypeError(f"seed={seed!r}: each entry must be an int or None, got {s!r}")
        return [None if s is None else int(s) for s in seeds]
    raise TypeError(f"seed must be None, an int or a list of num_envs={num_envs} ints, "
                    f"got {type(seed).__name__} {seed!r}")


def _check_reset_mask(mask, num_envs: int) -> np.ndarray:
    """gymnasium's checks of ``options["reset_mask"]``."""
    if not isinstance(mask, np.ndarray):
        raise TypeError(f"options['reset_mask'] must be a numpy array, got {type(mask).__name__}")
    if mask.shape != (num_envs,):
        raise ValueError(f"options['reset_mask'] must have shape ({num_envs},), got {mask.shape}")
    if mask.dtype != np.bool_:
        raise TypeError(f"options['reset_mask'] must have dtype=np.bool_, got {mask.dtype}")
    if not mask.any():
        raise ValueError(f"options['reset_mask']={mask!r} must contain at least one True")
    return mask


PARALLEL_MIN_ENVS = 128
"""From this many sub-envs on, ``parallel="auto"`` considers threads: it times
serial and threaded steps now and then and uses the faster (:mod:`.threads`)."""


class TetherLibrationVectorEnv(VectorEnv):
    r"""``num_envs`` independent libration environments stepped by one compiled kernel.

    The task, spaces, rewards, termination and arguments are those of
    :class:`~tether_gym.envs.TetherLibrationEnv` (see its docstring); this class only
    batches them. Build it with ``gym.make_vec("tether_gym/TetherLibration-v1",
    num_envs=n, **kwargs)`` (``vectorization_mode`` defaults to the vector entry point).

    ## Spaces

    ``single_observation_space`` and ``single_action_space`` are the single env's;
    ``observation_space`` is ``Box(float32, (num_envs, d))``, one single env's
    observation (size d = ``single_observation_space.shape[0]``, given with its layout
    in :class:`~tether_gym.envs.TetherLibrationEnv`) per row, and ``action_space``
    ``Box(-1, 1, (num_envs, N-1), float32)``. ``step`` takes a (num_envs, N-1) array; a
    wrong shape or a NaN/inf entry raises ValueError.

    ## Seeding and reset

    Every sub-env has its own ``np.random.Generator`` (``np_random`` is the tuple of
    them). ``reset(seed=s)`` seeds sub-env i with s + i, ``reset(seed=[s_0, ...])``
    with s_i (None entries keep or create a random generator), like gymnasium's
    ``SyncVectorEnv``; a later ``reset()`` without a seed continues each generator, as
    the single env does. ``options`` (the single env's reset options) apply to every
    sub-env that is reset; ``options["reset_mask"]`` (bool array, shape (num_envs,))
    resets only the masked sub-envs, the others keep their state and observation.

    ## Autoreset

    ``metadata["autoreset_mode"]`` is ``AutoresetMode.NEXT_STEP`` (gymnasium's default):
    after a sub-env terminates or truncates, the next ``step`` ignores its action,
    resets it (continuing its generator, without options) and returns its reset
    observation and info with reward 0 and terminated = truncated = False. An autoreset
    never raises: a start whose draws all fail begins an episode that is failed from the
    start and ends at its next step (the single env's Starting State).

    ## Episode End

    As in the single env: terminated on a failure (``info["failure"]``), truncated
    after ``orbits_per_episode`` orbits. ``max_episode_steps`` plays the role of the
    TimeLimit wrapper ``gym.make(..., max_episode_steps=k)`` adds to a single env: off
    by default (no step limit is registered), a sub-env is also truncated when its step
    count reaches k when given (None or -1 turn it off).

    ## Infos

    gymnasium's vector format: every key of the single env's ``info`` maps to an array
    over sub-envs (floats (num_envs,), arrays (num_envs, N-1), ``"failure"`` an object
    array of None or the failure name), with a boolean ``"_key"`` mask of the sub-envs
    that report it (all of them, except after a partial reset).

    ## Arguments

    ``num_envs`` (1 ... :data:`MAX_NUM_ENVS` = 4,194,304), ``max_episode_steps`` (see
    above), ``render_mode`` (None or "rgb_array"; ``render()`` returns one frame per
    sub-env), ``parallel`` (False:
    one thread; True: split the sub-envs into one chunk per core the process may use,
    each stepped by its own thread; "auto", the default: from ``PARALLEL_MIN_ENVS`` =
    128 sub-envs on, whichever of one thread and the threads measured faster lately,
    since threads pay on idle cores but can be many times slower when another process
    shares them (see :mod:`tether_gym.envs.threads`
    and bench/threads_under_load.py); the results are bitwise the same either way)
    and every keyword argument of the single env.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30,
                "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, max_episode_steps: int | None = None,
                 render_mode: str | None = None, parallel: bool | str = "auto", **kwargs):
        num_envs = check_num_envs(num_envs)
        if max_episode_steps is not None and (
                isinstance(max_episode_steps, bool)
                or not isinstance(max_episode_steps, (int, np.integer))
                or not (max_episode_steps >= 1 or max_episode_steps == -1)):
            raise ValueError(f"max_episode_steps={max_episode_steps!r} must be an int >= 1, "
                             "or None / -1 for no step limit")
        if render_mode == "human":
            raise ValueError("render_mode='human' is not supported by the vector env; use "
                             "'rgb_array' (render() returns one frame per sub-env) or None")
        if not (isinstance(parallel, (bool, np.bool_)) or parallel == "auto"):
            raise TypeError(f"parallel={parallel!r} must be True, False or 'auto'")
        self.config = EnvConfig.from_kwargs(render_mode=render_mode, **kwargs)
        self.num_envs = int(num_envs)
        self.max_episode_steps = (None if max_episode_steps in (None, -1)
                                  else int(max_episode_steps))
        self.render_mode = self.config.render_mode
        self.parallel = parallel if parallel == "auto" else bool(parallel)
        self.single_observation_space = observation_space(self.config)
        self.single_action_space = action_space(self.config)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._batch = ChainBatch(self.config, self.num_envs)
        self._rngs: list[np.random.Generator | None] = [None] * self.num_envs
        self._seeds: list[int | None] = [None] * self.num_envs
        self._autoreset = np.zeros(self.num_envs, dtype=np.bool_)
        self._all_rows = np.arange(self.num_envs, dtype=np.int64)
        self._was_reset = np.zeros(self.num_envs, dtype=np.bool_)
        self._renderer: Any = None

    # ------------------------------------------------------------------ #
    @property
    def n_tethers(self) -> int:
        """n = N - 1."""
        return self.config.n_tethers

    @property
    def model(self) -> TetherChain:
        """The nominal physics model (config's e and masses) for model-based controllers."""
        return self.config.model

    @property  # type: ignore[misc]
    def np_random(self) -> tuple[np.random.Generator, ...]:  # type: ignore[override]
        """The sub-envs' generators (a random seed is drawn for any not yet seeded)."""
        return tuple(self._rng(i) for i in range(self.num_envs))

    @property
    def np_random_seed(self) -> tuple[int | None, ...]:  # type: ignore[override]
        """The sub-envs' seeds (as gymnasium's ``Env.np_random_seed``)."""
        for i in range(self.num_envs):
            self._rng(i)
        return tuple(self._seeds)

    def _rng(self, i: int) -> np.random.Generator:
        rng = self._rngs[i]
        if rng is None:
            rng, self._seeds[i] = seeding.np_random()
            self._rngs[i] = rng
        return rng

    def _n_chunks(self, rows: int) -> int:
        """Threads for the next step (one chunk of rows each), 0 for the serial step."""
        policy = self.__dict__.get("_threads")
        if policy is None:
            policy = self._threads = ThreadPolicy(self.parallel, PARALLEL_MIN_ENVS)
        return policy.chunks(rows)

    # ------------------------------------------------------------------ #
    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None):
        """Reset every sub-env (or those of ``options["reset_mask"]``); see the class doc."""
        seeds = _check_seeds(seed, self.num_envs)
        if options is not None and not isinstance(options, dict):
            raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
        options = dict(options) if options else {}
        mask = None
        if "reset_mask" in options:
            mask = _check_reset_mask(options.pop("reset_mask"), self.num_envs)
        check_options(options or None, self.config)  # fail before touching any row
        rows = self._all_rows if mask is None else np.flatnonzero(mask)
        batch = self._batch
        for i in rows.tolist():
            if seeds[i] is not None:
                self._rngs[i], self._seeds[i] = seeding.np_random(seeds[i])
            self._rng(i)
        batch.reset_rows(rows, self._rngs, options or None)
        self._autoreset[rows] = False
        self._was_reset[rows] = True
        return batch.obs.copy(), self._infos(mask)

    def step(self, actions):
        """Step every sub-env; those that ended on the previous step are reset instead."""
        if not self._was_reset.all():
            raise RuntimeError(f"call reset() before step(); sub-envs "
                               f"{np.flatnonzero(~self._was_reset).tolist()} were never reset")
        batch = self._batch
        n = self.n_tethers
        raw = np.asarray(actions)
        if raw.dtype.kind not in "iuf":
            raise TypeError(f"actions must hold real numbers (no bools or complex), got dtype "
                            f"{raw.dtype}")
        a = np.ascontiguousarray(raw, dtype=np.float64)
        if a.shape != (self.num_envs, n):
            raise ValueError(f"actions must have shape ({self.num_envs}, {n}) (num_envs, N-1), "
                             f"got {a.shape}: {actions!r}")
        if not np.isfinite(a).all():  # checked here: autoreset rows ignore their action
            bad = np.flatnonzero(~np.isfinite(a).all(axis=1))
            raise ValueError(f"actions must be finite (no NaN or inf); rows {bad.tolist()} are "
                             f"not: {a[bad]!r}")
        done = self._autoreset
        if done.any():
            rows = np.flatnonzero(~done)
            ended = np.flatnonzero(done)
            if len(rows):
                # the ended rows are reset while the worker threads step the others (or
                # after the step): disjoint rows, each with its own generator
                chunks = self._n_chunks(len(rows))
                start = time.perf_counter()
                batch.step(a, self._rngs, rows, chunks, checked=True,
                           meanwhile=lambda: batch.reset_rows(ended, self._rngs))
                self._threads.record(len(rows), time.perf_counter() - start)
            else:
                batch.reset_rows(ended, self._rngs)
        else:
            chunks = self._n_chunks(self.num_envs)
            start = time.perf_counter()
            batch.step(a, self._rngs, None if chunks == 0 else self._all_rows, chunks,
                       checked=True)
            self._threads.record(self.num_envs, time.perf_counter() - start)
        # reset rows have failure 0, steps 0 and nu < nu_end: neither flag is set for them
        terminated = batch.failure != 0
        truncated = batch.truncated() & ~terminated
        if self.max_episode_steps is not None:
            truncated |= batch.steps >= self.max_episode_steps
        self._autoreset = terminated | truncated
        return batch.obs.copy(), batch.reward.copy(), terminated, truncated, self._infos(None)

    def _infos(self, mask: np.ndarray | None) -> dict[str, Any]:
        """gymnasium vector infos; with a mask, only those sub-envs report (zeros elsewhere)."""
        values = self._batch.info_arrays()
        infos: dict[str, Any] = {}
        if mask is None:
            # one buffer for all the "_key" masks: each key still gets its own row of it
            every = np.ones((len(values), self.num_envs), dtype=np.bool_)
            pairs = chain.from_iterable(zip(values.values(), every, strict=True))
            return dict(zip(_PAIRED_KEYS, pairs, strict=True))
        for key, value in values.items():
            if value.dtype == object:
                value[~mask] = None
            else:
                value[~mask] = 0
            infos[key] = value
            infos["_" + key] = mask.copy()
        return infos

    # ------------------------------------------------------------------ #
    def render(self) -> tuple[np.ndarray, ...] | None:
        """One (H, W, 3) uint8 frame per sub-env in "rgb_array" mode."""
        if self.render_mode is None:
            logger.warn("render() called without a render_mode; pass render_mode='rgb_array' "
                        "to gym.make_vec")
            return None
        if not self._was_reset.all():
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            from .rendering import ChainRenderer

            self._renderer = ChainRenderer(self.config, self.render_mode)
        batch = self._batch
        return tuple(self._renderer.draw(batch.info(i), eccentricity_of(batch, i))
                     for i in range(self.num_envs))

    def close_extras(self, **kwargs: Any) -> None:
        """Stop worker threads and close the renderer."""
        self._batch.close()
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __repr__(self) -> str:
        return (f"TetherLibrationVectorEnv(num_envs={self.num_envs}, "
                f"n_bodies={self.config.n_bodies}, e={self.config.eccentricity})")

