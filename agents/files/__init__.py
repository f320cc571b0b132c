"""Agent files and run folders: the one owner of what trained agents and runs leave on disk.

The safe agent format (``agent.json`` + ``policy.safetensors``: plain data and tensors,
loading never runs code), the layout of ``train.py``'s run folders, the opt-in reading
of stable-baselines3's pickled runs, :class:`TrainedAgent` (a loaded agent with the common
``predict``), export and conversion (``python -m tether_gym_agents.files``). Every file
read from an agent or run folder is a regular file inside it.

Every module of this package, with what it holds: the diagram of docs/architecture.md
(the one list of modules).
"""

from .run_folder import seed_runs
from .safe_format import AgentLoadError, ObsNormalization, load_agent, save_agent
from .trained import TrainedAgent, hybrid_of, pretrained_agents

__all__ = ["TrainedAgent", "hybrid_of", "pretrained_agents", "seed_runs", "AgentLoadError",
           "ObsNormalization", "save_agent", "load_agent"]
