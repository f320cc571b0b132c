"""Plain-data helpers shared by the agent files, the run folders and results.json."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["to_jsonable", "sha256_file", "checked_mapping", "loads_json"]


def to_jsonable(x):
    """``x`` with numpy scalars/arrays as Python values, tuples as lists, NaN/inf as None.

    The result is strict JSON (and plain YAML): no numpy types, no NaN tokens.
    """
    if isinstance(x, dict):
        return {str(k): to_jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [to_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return to_jsonable(x.tolist())
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, Path):
        return str(x)
    return x


def checked_mapping(data, keys: tuple[str, ...], what: str) -> dict:
    """``data`` if it is a mapping whose keys are among ``keys``.

    Raises
    ------
    ValueError
        For a non-mapping or an unknown key; the message names ``what`` and the valid keys.
    """
    if not isinstance(data, dict):
        raise ValueError(f"{what} must be a mapping with keys {list(keys)}, got {data!r}")
    unknown = sorted(str(k) for k in set(data) - set(keys))
    if unknown:
        raise ValueError(f"{what}: unknown key(s) {unknown}; valid keys: {list(keys)}")
    return data


def sha256_file(path: Path) -> str:
    """SHA-256 hex digest of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def loads_json(text: str | bytes, source) -> Any:
    """The JSON document ``text`` read from ``source`` (a file's name, for the message).

    Raises
    ------
    ValueError
        Naming ``source``, for text that is not UTF-8 JSON or is nested too deeply for
        Python's decoder (which recurses per level: 100k ``[`` were a RecursionError).
    """
    try:
        return json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{source} is not valid JSON: {exc}") from None
    except RecursionError:
        raise ValueError(f"{source} is not valid JSON here: nested too deeply") from None
