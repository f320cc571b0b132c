"""``python -m tether_gym_agents.files``: see :mod:`tether_gym_agents.files.cli`."""

from .cli import main

raise SystemExit(main())
