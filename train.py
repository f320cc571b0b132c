"""Train an agent (PPO, SAC, TQC or TD3) on tether_gym: ``python train.py --help``."""
import sys

try:
    from tether_gym_agents.cli.train import main

    sys.exit(main())
except ModuleNotFoundError as exc:  # an optional dependency: one line, not a traceback
    if (exc.name or "tether_gym").startswith("tether_gym"):
        raise
    hint = str(exc) if "pip install" in str(exc) else (
        f"{exc.name} is not installed; in a clone of tether_gym: "
        'pip install torch==2.13.0 && pip install -e ".[train]"')
    print(f"train.py: error: {hint}", file=sys.stderr)
    sys.exit(2)
