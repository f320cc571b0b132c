"""Benchmark policies (``python evaluate.py [bench] ...``) or reproduce the paper
(``python evaluate.py paper --out DIR``): ``python evaluate.py -h``."""
import sys

from tether_gym_agents.cli.evaluate import main

sys.exit(main())
