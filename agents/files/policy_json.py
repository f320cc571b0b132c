"""A stable-baselines3 policy's spaces and constructor settings as plain JSON, and back.

Class-valued settings (the activation, the features extractor) are stored by name and
looked up in fixed allow-lists on the way back, never imported from a file.
"""

from __future__ import annotations

import json
import math

import numpy as np

__all__ = ["PolicyJsonError", "float_list", "float_array", "space_to_json", "space_from_json",
           "settings_to_json", "settings_from_json"]

ACTIVATIONS = ("Tanh", "ReLU", "ELU", "LeakyReLU", "GELU", "SiLU", "Sigmoid", "Softplus",
               "Mish")
EXTRACTORS = ("FlattenExtractor",)
SKIP_SETTINGS = ("observation_space", "action_space", "lr_schedule", "optimizer_class",
                 "optimizer_kwargs")
"""Constructor settings that only matter for training (the optimiser) or are rebuilt."""


class PolicyJsonError(ValueError):
    """A recorded space or policy setting is malformed or not in the allow-list."""


def float_list(arr) -> list:
    """Floats as JSON numbers; inf/nan as the strings "inf", "-inf", "nan" (strict JSON)."""
    out = []
    for x in np.asarray(arr, dtype=np.float64).ravel().tolist():
        out.append(x if math.isfinite(x) else repr(x))
    return out


def float_array(values, shape, dtype, what: str) -> np.ndarray:
    """The inverse of :func:`float_list`, reshaped; a bad entry is a PolicyJsonError."""
    try:
        arr = np.array([float(v) for v in values], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise PolicyJsonError(f"{what}: {exc}") from None
    need = math.prod(shape)
    if arr.size != need:
        raise PolicyJsonError(f"{what} has {arr.size} entries; allowed: {need} (one per entry "
                              f"of shape {list(shape)})")
    return arr.reshape(shape).astype(dtype)


def space_to_json(space) -> dict:
    """A Box space as plain data (type, shape, dtype, bounds)."""
    from gymnasium import spaces

    if not isinstance(space, spaces.Box):
        raise TypeError(f"only Box spaces can be saved, got {type(space).__name__}")
    return {"type": "Box", "shape": list(space.shape), "dtype": str(space.dtype),
            "low": float_list(space.low), "high": float_list(space.high)}


def space_from_json(data: dict, what: str):
    """The Box space recorded by :func:`space_to_json`."""
    from gymnasium import spaces

    try:
        if data["type"] != "Box":
            raise PolicyJsonError(f"{what}: only Box spaces are supported, got "
                                  f"{data['type']!r}")
        shape = tuple(int(s) for s in data["shape"])
        dtype = np.dtype(data["dtype"])
        if dtype.kind != "f":
            raise PolicyJsonError(f"{what}: dtype {dtype} is not a float type")
        low = float_array(data["low"], shape, dtype, f"{what}.low")
        high = float_array(data["high"], shape, dtype, f"{what}.high")
    except (KeyError, TypeError) as exc:
        raise PolicyJsonError(f"{what} is malformed ({exc!r})") from None
    return spaces.Box(low=low, high=high, shape=shape, dtype=dtype)


def settings_to_json(params: dict) -> dict:
    """A policy's constructor settings as plain data (TypeError for anything else)."""
    out = {}
    for key, value in params.items():
        if key in SKIP_SETTINGS:
            continue
        if key == "activation_fn":
            name = value.__name__
            if name not in ACTIVATIONS or value.__module__.split(".")[0] != "torch":
                raise TypeError(f"activation_fn {value!r} cannot be saved; supported: "
                                f"{ACTIVATIONS}")
            out[key] = name
        elif key == "features_extractor_class":
            if value.__name__ not in EXTRACTORS:
                raise TypeError(f"features_extractor_class {value!r} cannot be saved; "
                                f"supported: {EXTRACTORS}")
            out[key] = value.__name__
        else:
            json.dumps(value)  # TypeError for anything that is not plain data
            out[key] = value
    return out


def settings_from_json(data: dict) -> dict:
    """The constructor settings recorded by :func:`settings_to_json`, classes looked up."""
    import torch.nn as nn
    from stable_baselines3.common import torch_layers

    if not isinstance(data, dict):
        raise PolicyJsonError(f"policy_kwargs must be a mapping, got {data!r}")
    out = dict(data)
    if "activation_fn" in out:
        if out["activation_fn"] not in ACTIVATIONS:
            raise PolicyJsonError(f"activation_fn {out['activation_fn']!r} is not one of "
                                  f"{ACTIVATIONS}")
        out["activation_fn"] = getattr(nn, out["activation_fn"])
    if "features_extractor_class" in out:
        if out["features_extractor_class"] not in EXTRACTORS:
            raise PolicyJsonError(f"features_extractor_class "
                                  f"{out['features_extractor_class']!r} is not one of "
                                  f"{EXTRACTORS}")
        out["features_extractor_class"] = getattr(torch_layers, out["features_extractor_class"])
    return out
