"""The observation and the ``info`` entries of the libration environments, declared once.

The compiled step (:mod:`tether_gym.envs.step_kernel`) writes both through the
offsets derived here (``O`` and ``I``); the environments build their observation
space, the ``info`` dicts and the docstring tables from the same declarations, and
``tether_gym_agents`` reads observations with :data:`OBSERVATION` too. Adding an
observation field or an info entry means adding a :class:`Field` here and the line of
the step kernel that computes it.

``info`` entries live in two buffers: one value per entry (``Field.per_tether``
False) in ``scalars[c0]``, one array per entry in ``vectors[c1]``, where (c0, c1) is
the entry's :attr:`Layout.index` pair. ``failure`` holds the :class:`Failure` code
and becomes its label (None while healthy) in the dict.
"""

from __future__ import annotations

import operator

import numpy as np

from ..physics.layout import Field, Layout
from ..tasks.cost import COST_PARTS
from ..tasks.reward import COMPONENTS, MARGINS, PENALTIES
from ..tasks.termination import Failure

__all__ = ["OBSERVATION", "INFO", "O", "I", "INFO_KEYS", "info_dict", "observation_bounds",
           "markdown_table", "N_INFO_SCALARS", "N_INFO_VECTORS"]

OBSERVATION = Layout("observation", (
    Field("sin_nu", False, "[-]", "sin(nu): orbital phase", -1.0, 1.0),
    Field("cos_nu", False, "[-]", "cos(nu): orbital phase", -1.0, 1.0),
    Field("theta", True, "[rad]", "theta_i"),
    Field("dtheta", True, "[rad/rad]", "theta_i' = d theta_i / d nu"),
    Field("length", True, "[-]", "l_i"),
    Field("dlength", True, "[-]", "l_i' (actual reel rates)"),
    Field("theta_ref", False, "[rad]", "theta_d (reference)"),
    Field("dtheta_ref", False, "[rad/rad]", "theta_d' (reference)"),
    Field("error", True, "[rad]", "e_i = theta_i - theta_d"),
    Field("derror", True, "[rad/rad]", "e_i' = theta_i' - theta_d'"),
    Field("log_length", True, "[-]", "ln(l_i / l_i,nom)"),
    Field("command", True, "[-]", "u_i, the normalised reel-rate command in force", -1.0, 1.0),
    Field("eccentricity", False, "[-]", "eccentricity e", optional="eccentricity"),
    Field("mass_fractions", True, "[-]", "mass fractions M_i", optional="masses"),
))
O = OBSERVATION.index
"""Offsets of the observation's fields."""

_SWITCH_DOCS = {"eccentricity": "observe_params True or \"eccentricity\"",
                "masses": "observe_params True"}
"""What turns each optional observation group on, for the docstring tables."""

_COMPONENT_DOCS = {"reward_tracking": "(1 - W) r_track, the tracking part of the reward",
                   **{f"reward_{name}": "reward penalty (<= 0)" for name in PENALTIES},
                   **{f"reward_{name}": "reward margin term (>= 0)" for name in MARGINS}}

_COST_DOCS = {"cost": "constraint cost, cost_slack + cost_length + cost_tumble (v2)",
              "cost_slack": "1 if a tension fell below T_c during the step, else 0",
              "cost_length": "1 if a length is within a factor f of a length bound, else 0",
              "cost_tumble": "1 if a libration reached g pi/2, else 0"}
assert set(_COST_DOCS) == {"cost", *(f"cost_{part}" for part in COST_PARTS)}

INFO = Layout("info", (
    Field("nu", False, "[rad]", "true anomaly (not wrapped)"),
    Field("theta", True, "[rad]", "libration angles"),
    Field("dtheta", True, "[rad/rad]", "theta'"),
    Field("length", True, "[-]", "tether lengths"),
    Field("dlength", True, "[-]", "reel rates l'"),
    Field("ddlength", True, "[-]", "reel accelerations l'' at the end of the step"),
    Field("tension", True, "[-]", "tensions T^ at the end of the step"),
    Field("tension_min", True, "[-]", "smallest T^ at the physics substeps of the step"),
    Field("theta_ref", False, "[rad]", "theta_d"),
    Field("dtheta_ref", False, "[rad/rad]", "theta_d'"),
    Field("reel_accel", True, "[m/s^2]", "physical reel accelerations L_ddot"),
    Field("command", True, "[-]", "u_i, normalised reel-rate command of the step"),
    Field("eccentricity", False, "[-]", "e of the episode"),
    Field("failure", False, "[-]", "None, or why the episode terminated"),
) + tuple(Field(name, False, "[-]", _COMPONENT_DOCS[name])
          for name in COMPONENTS)
  + tuple(Field(name, False, "[-]", doc) for name, doc in _COST_DOCS.items()))
I = INFO.index  # noqa: E741 - the info layout's index, beside O
"""Buffer index of each info entry: ``scalars[I.nu[0]]``, ``vectors[I.theta[1]]``."""

INFO_KEYS = INFO.names
"""Keys of the ``info`` dict, in order."""

_FAILURE_LABELS = np.empty(len(Failure), dtype=object)
_FAILURE_LABELS[:] = [Failure(code).label for code in range(len(Failure))]
_SCALARS = tuple(f.name for f in INFO if not f.per_tether)
_VECTORS = tuple(f.name for f in INFO if f.per_tether)


N_INFO_SCALARS = len(_SCALARS)
"""Rows of the scalar info buffer."""
N_INFO_VECTORS = len(_VECTORS)
"""Rows of the per-tether info buffer."""


_PICK = operator.itemgetter(*[
    _SCALARS.index(f.name) if not f.per_tether else len(_SCALARS) + _VECTORS.index(f.name)
    for f in INFO])
"""Picks the INFO_KEYS order out of the scalar entries followed by the vector entries."""


def info_dict(scalars, vectors) -> dict:
    """The ``info`` dict from the two buffers' entries of one env or of all (INFO_KEYS order).

    ``scalars`` is a list of floats (or of (num,) arrays) and ``vectors`` a list of (n,)
    (or (num, n)) arrays, in the buffers' row order.
    """
    info = dict(zip(INFO_KEYS, _PICK([*scalars, *vectors]), strict=True))
    code = info["failure"]
    info["failure"] = (_FAILURE_LABELS[int(code)] if isinstance(code, float)
                       else _FAILURE_LABELS[np.asarray(code, dtype=np.int64)])
    return info


def observation_bounds(n: int, switches: dict[str, bool]) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) float32 arrays of the observation box for n tethers.

    ``switches`` turns the optional groups on (``EnvConfig.observed``).
    """
    low = np.full(OBSERVATION.size(n, **switches), -np.inf, dtype=np.float32)
    high = -low
    for name, sl in OBSERVATION.slices(n, **switches).items():
        low[sl] = OBSERVATION[name].low
        high[sl] = OBSERVATION[name].high
    return low, high


def _offset_text(c0: int, c1: int) -> str:
    """``c0 + c1 n`` as the docstring tables write it (e.g. ``2n+2``)."""
    if c1 == 0:
        return str(c0)
    term = "n" if c1 == 1 else f"{c1}n"
    return term if c0 == 0 else f"{term}+{c0}"


def markdown_table(layout: Layout, title: str = "Field", keyed: bool = False) -> str:
    """A markdown table of a layout for docstrings: index range (or key), meaning, unit."""
    lines = [f"| {'Key' if keyed else 'Index'} | {title} | Unit |", "|---|---|---|"]
    for f in layout:
        c0, c1 = getattr(layout.index, f.name)
        if keyed:
            index = f"``{f.name!r}``" + (" (n,)" if f.per_tether else "")
        else:
            index = _offset_text(c0, c1)
            if f.per_tether:
                index += " .. " + _offset_text(c0 - 1, c1 + 1)
        note = f" (with {_SWITCH_DOCS.get(f.optional, f.optional)})" if f.optional else ""
        lines.append(f"| {index} | {f.doc}{note} | {f.unit} |")
    return "\n".join(lines)
