"""Agent files and run folders: the one owner of what trained agents and runs leave on disk.

Modules by job:

* :mod:`.safe_format`: the safe agent format (``agent.json`` + ``policy.safetensors``),
  save and load; :mod:`.policy_json` turns a policy's spaces and settings into plain data;
  :mod:`.agent_values` bounds the values of ``agent.json`` (checked before anything is built).
* :mod:`.folder_paths`: every file read from an agent or run folder is a regular file inside it.
* :mod:`.run_folder`: the layout of ``train.py``'s run folders and folders of seed runs
  (file names, readers, atomic writers).
* :mod:`.pickled`: stable-baselines3's pickled run folders, loaded on explicit opt-in;
  :mod:`.zoo_folder` the layout and YAML of rl-baselines3-zoo's run folders.
* :mod:`.trained`: :class:`TrainedAgent`, a loaded agent with the common ``predict``;
  :mod:`.mlp` its batch-invariant forward pass.
* :mod:`.export`: copy the shareable files of runs, convert pickled runs.
* :mod:`.cli`: ``python -m tether_gym_agents.files {convert,export}``.
"""

from .run_folder import seed_runs
from .safe_format import AgentLoadError, ObsNormalization, load_agent, save_agent
from .trained import TrainedAgent, hybrid_of, pretrained_agents

__all__ = ["TrainedAgent", "hybrid_of", "pretrained_agents", "seed_runs", "AgentLoadError",
           "ObsNormalization", "save_agent", "load_agent"]
