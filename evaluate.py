"""Evaluate policies on the scenario suite or reproduce the paper: ``python evaluate.py -h``."""
import sys

from tether_gym_agents.evaluation import main

sys.exit(main())
