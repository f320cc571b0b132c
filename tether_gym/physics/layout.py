"""Flat float rows described once: a :class:`Layout` is an ordered list of fields.

Every row the compiled kernels exchange with Python (the chain's state, its
parameters, the observation, the ``info`` entries) is declared once as a Layout in
the module that owns it: :data:`tether_gym.physics.state.STATE` and
:data:`~tether_gym.physics.state.PARAMS`, :data:`tether_gym.envs.layout.OBSERVATION`
and :data:`~tether_gym.envs.layout.INFO`. A field holds one value or one value per
tether (n = N-1 of them), so its offset in a row is ``c0 + c1 n`` with integers c0, c1
fixed by the fields before it. The kernels read offsets from :meth:`Layout.index`
(a named tuple of (c0, c1) pairs, a compile-time constant for numba) through
:func:`at`; Python code gets slices and sizes from the same declaration.

Optional groups are nested: because the offsets are static, a group switched on needs
every optional group declared before it on too (the offsets of its fields count the
earlier groups). :meth:`Layout.selected`, :meth:`~Layout.size` and :meth:`~Layout.slices`
raise ValueError for any other combination, naming the groups, instead of giving
slices past the end of the row.
"""

from __future__ import annotations

from collections import namedtuple
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from numba import njit

from .jit import LOOP

__all__ = ["Field", "Layout", "at"]


@dataclass(frozen=True)
class Field:
    """One entry of a row.

    Parameters
    ----------
    name : str
        Identifier (a valid Python name).
    per_tether : bool
        True: n values (one per tether); False: one value.
    unit : str
        Unit in brackets, e.g. ``"[rad]"``, ``"[-]"``.
    doc : str
        One line for tables and docstrings.
    low, high : float
        Bounds of the value (observation space), -inf/inf when unbounded.
    optional : str or None
        Name of the switch that includes the field (e.g. ``"eccentricity"``); optional
        fields must come after every mandatory one, the fields of one group next to each
        other, and a group is present only with every group declared before it.
    """

    name: str
    per_tether: bool
    unit: str
    doc: str
    low: float = float("-inf")
    high: float = float("inf")
    optional: str | None = None


class Layout:
    """An ordered set of :class:`Field` s forming one flat float row.

    Parameters
    ----------
    name : str
        Name of the row (used for the index type's name).
    fields : sequence of Field
        The fields in row order.

    Raises
    ------
    ValueError
        When a field name repeats, a mandatory field follows an optional one, or the
        fields of one optional group are not next to each other.
    """

    def __init__(self, name: str, fields: tuple[Field, ...]):
        names = [f.name for f in fields]
        if len(set(names)) != len(names):
            raise ValueError(f"layout {name!r} repeats a field name: {names}")
        groups: list[str] = []
        for f in fields:
            if f.optional is None and groups:
                raise ValueError(f"layout {name!r}: mandatory field {f.name!r} after an "
                                 "optional one")
            if f.optional is not None and f.optional != (groups[-1] if groups else None):
                if f.optional in groups:
                    raise ValueError(f"layout {name!r}: field {f.name!r} of optional group "
                                     f"{f.optional!r} is not next to the group's other "
                                     f"fields (groups in row order: {groups})")
                groups.append(f.optional)
        self.name = name
        self.fields = tuple(fields)
        self._groups = tuple(groups)
        c0 = c1 = 0
        offsets = []
        for f in self.fields:
            offsets.append((c0, c1))
            if f.per_tether:
                c1 += 1
            else:
                c0 += 1
        index_type = namedtuple(name.title().replace("_", "") + "Index", names)  # type: ignore[misc]
        self._index = index_type(*offsets)
        self._slices: dict[tuple, dict[str, slice]] = {}  # (n, switches) -> slices

    @property
    def index(self) -> Any:
        """Named tuple of (c0, c1) per field: the offset is ``c0 + c1 n`` (see :func:`at`)."""
        return self._index

    @property
    def names(self) -> tuple[str, ...]:
        """Field names in row order."""
        return tuple(f.name for f in self.fields)

    def __iter__(self) -> Iterator[Field]:
        return iter(self.fields)

    def __getitem__(self, name: str) -> Field:
        for f in self.fields:
            if f.name == name:
                return f
        raise KeyError(f"layout {self.name!r} has no field {name!r}; fields: {list(self.names)}")

    @property
    def groups(self) -> tuple[str, ...]:
        """Names of the optional groups (the switches), in row order."""
        return self._groups

    def check_switches(self, **switches: bool) -> None:
        """Raise ValueError unless the switches name groups of this layout and are nested.

        A group switched on needs every group declared before it on: the offsets are
        static (:attr:`index`), so its fields are only where they are said to be when the
        earlier groups are present.
        """
        unknown = sorted(set(switches) - set(self._groups))
        if unknown:
            raise ValueError(f"layout {self.name!r} has no optional group {unknown}; "
                             f"groups: {list(self._groups)}")
        for k, group in enumerate(self._groups):
            off = [g for g in self._groups[:k] if not switches.get(g)]
            if switches.get(group) and off:
                raise ValueError(f"layout {self.name!r}: optional group {group!r} is on but "
                                 f"{off} declared before it is off; a group needs every "
                                 f"earlier group on (groups in row order: "
                                 f"{list(self._groups)})")

    def selected(self, **switches: bool) -> tuple[Field, ...]:
        """The fields present when the optional groups are switched as given.

        Raises ValueError (:meth:`check_switches`) for an unknown group or a group on
        while one declared before it is off.
        """
        self.check_switches(**switches)
        return tuple(f for f in self.fields if f.optional is None or switches.get(f.optional))

    def size(self, n: int, **switches: bool) -> int:
        """Length of the row for n tethers with the given optional groups."""
        return sum(n if f.per_tether else 1 for f in self.selected(**switches))

    def slices(self, n: int, **switches: bool) -> dict[str, slice]:
        """Slice of every present field in a row for n tethers (a new dict each call).

        Computed once per (n, switches) and copied from then on: observation readers
        call it at every control step.
        """
        key = (n, tuple(sorted(switches.items())))
        known = self._slices.get(key)
        if known is None:
            known = {}
            for f in self.selected(**switches):
                c0, c1 = getattr(self._index, f.name)
                start = c0 + c1 * n
                known[f.name] = slice(start, start + (n if f.per_tether else 1))
            self._slices[key] = known
        return dict(known)

    def __repr__(self) -> str:
        return f"Layout({self.name!r}, {list(self.names)})"


@njit(**LOOP)
def at(spec, n):
    """Offset ``c0 + c1 n`` of a field whose :attr:`Layout.index` entry is ``spec``.

    Compiled for the kernels; with ``spec`` a global constant LLVM inlines it and
    folds it to one addition.
    """
    return spec[0] + spec[1] * n
