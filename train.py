"""Train a PPO or SAC agent on tether_gym: ``python train.py --help``."""
import sys

from tether_gym_agents.training import main

sys.exit(main())
