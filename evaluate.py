"""Benchmark policies (``python evaluate.py [bench] ...``) or reproduce the paper
(``python evaluate.py paper --out DIR``): ``python evaluate.py -h``."""
import sys

try:
    from tether_gym_agents.cli.evaluate import main

    sys.exit(main())
except ModuleNotFoundError as exc:  # an optional dependency: one line, not a traceback
    if (exc.name or "tether_gym").startswith("tether_gym"):
        raise
    hint = str(exc) if "pip install" in str(exc) else (
        f"{exc.name} is not installed; in a clone of tether_gym: "
        'pip install torch==2.13.0 && pip install -e ".[train]"')
    print(f"evaluate.py: error: {hint}", file=sys.stderr)
    sys.exit(2)
