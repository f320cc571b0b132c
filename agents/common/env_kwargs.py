"""``--env-kwargs key=value ...``: env arguments typed on the command line.

Values are Python literals read by :func:`ast.literal_eval` (numbers, strings, tuples,
lists, dicts, True/False/None); nothing is evaluated as code. A bare word such as
``gravity=full`` is taken as the string ``"full"``; anything else that is not a literal
(``masses=(1,2``) is an error that names the flag.
"""

from __future__ import annotations

import ast
import re

__all__ = ["parse_env_kwargs"]

_BARE_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*\Z")
_WORDS = {"true": True, "false": False, "none": None, "null": None}


def parse_env_kwargs(items, flag: str = "--env-kwargs") -> dict:
    """``["key=value", ...]`` -> ``{key: value}``.

    Raises
    ------
    ValueError
        On an entry without ``=``, a key that is not a Python name, a repeated key or a
        value that is neither a literal nor a bare word; the message names ``flag``.
    """
    out: dict = {}
    for item in items or []:
        if not isinstance(item, str) or "=" not in item:
            raise ValueError(f"{flag} {item!r}: each entry must look like key=value, e.g. "
                             "eccentricity=0.3 or masses=(1,2)")
        key, text = item.split("=", 1)
        key = key.strip()
        if not key.isidentifier():
            raise ValueError(f"{flag}: key {key!r} in {item!r} is not a valid argument name")
        if key in out:
            raise ValueError(f"{flag}: {key!r} is given twice")
        text = text.strip()
        try:
            value = ast.literal_eval(text)
        except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError):
            if not _BARE_WORD.match(text):
                raise ValueError(f"{flag} {item!r}: {text!r} is not a Python literal; allowed: "
                                 "numbers, True/False/None, tuples/lists like (1, 2), quoted "
                                 "strings or bare words like full") from None
            value = _WORDS.get(text.lower(), text)
        out[key] = value
    return out
