"""Agent files and run folders: the safe agent format, loading trained agents, export."""

from .agent_files import seed_runs
from .trained import TrainedAgent, hybrid_of, pretrained_agents

__all__ = ["TrainedAgent", "hybrid_of", "pretrained_agents", "seed_runs"]
