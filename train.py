"""Train an agent (PPO, SAC, TQC or TD3) on tether_gym: ``python train.py --help``."""
import sys

from tether_gym_agents.cli.train import main

sys.exit(main())
