"""Former home of the agent files, kept so that old imports and commands keep working.

``python -m tether_gym_agents.files.agent_files {convert,export}`` is
``python -m tether_gym_agents.files {convert,export}``. New code imports from the
modules by job: :mod:`~tether_gym_agents.files.safe_format` (save, load),
:mod:`~tether_gym_agents.files.pickled` (opt-in loader of pickled runs),
:mod:`~tether_gym_agents.files.export` (export, convert) and
:mod:`~tether_gym_agents.files.run_folder` (the run-folder layout).
"""

from .cli import main
from .export import convert_run, export_runs
from .pickled import PICKLED_MODEL_FILES, load_pickled_run, run_features, run_hybrid
from .run_folder import seed_runs
from .safe_format import (
    AGENT_FILE,
    FORMAT,
    FORMAT_VERSION,
    WEIGHTS_FILE,
    AgentLoadError,
    is_unit,
    load_agent,
    save_agent,
)

__all__ = ["AgentLoadError", "AGENT_FILE", "WEIGHTS_FILE", "FORMAT", "FORMAT_VERSION",
           "save_agent", "load_agent", "load_pickled_run", "convert_run", "export_runs",
           "is_unit", "PICKLED_MODEL_FILES", "run_hybrid", "run_features", "seed_runs", "main"]

if __name__ == "__main__":
    raise SystemExit(main())
