"""Reproduce Shi, Zhu & Zhu (2019), Figs. 2-9, from the environment and the baselines.

``python evaluate.py paper --out DIR`` (or :func:`main`) runs every study of the
paper through ``gym.make("tether_gym/TetherLibration-v1", ...)`` with the policies of
this package, writes the figures as PNG files into DIR and a table
``paper_vs_tether_gym.md`` (+ ``.json``) that puts every number the paper states
beside ours, with a verdict. Where docs/model.md explains a
difference, the table checks that explanation with its own run.

Modules
-------
* ``settings``: the env arguments and constants of the studies;
* ``runs``: one episode of a baseline through the benchmark's rollout;
* ``studies``: the runs of each study and the numbers taken from them;
* ``measures``: swing, chattering and the sliding-mode numbers;
* ``figures``: the PNG files; ``table``: the rows and the Markdown page;
* ``cli``: :func:`reproduce` (all of the above in order) and ``evaluate.py paper``.

Studies and settings
--------------------
* Zero state (Figs. 2-4): Eq. 7 (:class:`~tether_gym_agents.baselines.open_loop.ZeroStateReel`)
  from theta = theta' = 0 (reference amplitude 0), Table 1, 3 orbits.
* Periodic solutions (Fig. 5, e = 0.2, A = 0.1, 0.2, 0.3; Fig. 6, e = 0.7,
  p = 7100 (1 + e) km, A = 0.5 ... 0.9): Eq. 10 on the reference
  (:class:`~tether_gym_agents.baselines.open_loop.PeriodicReel`) from theta = 0, theta' = A.
* Swing minimiser (Eq. 11b) and the tension-positivity polynomial (Sec. 3.2): scans of
  the same open-loop runs over A and e.
* Sliding mode (Figs. 7-9): :class:`~tether_gym_agents.baselines.smc.SlidingModeController`
  (c = k = 1, eps = 0.1) from the Sec. 4.3 state with the 0.01 m/s^2 reel
  acceleration limit (L0 = 20 km), once at the paper's step (control step = RK4 step
  = 0.001 rad, reel lag 0.001 rad, close to the paper's ideal reel with a
  backward-difference l'') and once at the env's default control step (0.025 rad).

The open-loop studies have no acceleration limit (``accel_limit=None``, as in the
paper) and no practical rate limit (``max_reel_rate=10``), and run at control step =
RK4 step h_c = 0.001 rad with a reel lag tau = 0.005 rad
(:data:`OPEN_LOOP_SETTINGS`). The law is held over each control step, and at every
command change the reel's l'' jumps: on a steady ramp of slope s it swings between
s x / (1 - e^-x) and s x e^-x / (1 - e^-x), x = h_c / tau. With tau = h_c (x = 1) that
is 1.58 s ... 0.58 s, and the resulting tension dips slacken the tether at e = 0.2,
A = 0.6 although the exact law keeps T^_2 >= 0.25; with x = 0.2 the swing is +-10 %,
at the cost of a delay h_c / 2 + tau = 0.0055 rad. The positivity rows also report
the model's tension along the exact reference (no env) to separate the two effects.

Definitions used in the table
-----------------------------
* swing of a tether = (max l - min l) / l(0) over one orbit (docs/model.md's measure;
  "peak reel-out" = max l / l(0) - 1 is reported beside it);
* convergence time [orbits] = the first nu after which max_i |theta_i - theta_d|
  stays below 1e-3 rad to the end of the run;
* chattering, over the run after convergence (after orbit 1 if it never converges),
  on the commanded reel rates u_i = l'_cmd,i: total variation per orbit, the
  high-frequency fraction of that variation and the number of local extrema of u_i
  per orbit (see :func:`chattering`).
"""

from ..evaluation.rollout import Trajectory, rollout
from .cli import main, reproduce
from .measures import chattering, convergence_orbits, swing
from .settings import DEFAULT_SMC_SETTINGS, OPEN_LOOP_SETTINGS, PAPER_SMC_SETTINGS

__all__ = [
    "main",
    "reproduce",
    "rollout",
    "Trajectory",
    "convergence_orbits",
    "chattering",
    "swing",
    "OPEN_LOOP_SETTINGS",
    "PAPER_SMC_SETTINGS",
    "DEFAULT_SMC_SETTINGS",
]
