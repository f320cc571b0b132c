"""Train a PPO or SAC agent on tether_gym: ``python train.py --help``."""
import sys

from tether_gym_agents.cli.train import main

sys.exit(main())
