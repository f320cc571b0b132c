"""Learning curves on the benchmark itself, against env steps and wall-clock time.

A training run writes each checkpoint's policy as a safe agent folder that records its
env steps and the run's wall time then (``checkpoints/agent_<N>_steps/``, see
:mod:`tether_gym_agents.files.run_folder`). :func:`learning_curves` evaluates them
afterwards, on a scenario suite (the default one unless told), exactly as
``python evaluate.py`` scores a policy: at every checkpoint step that all seeds have
reached, the seeds' checkpoints form one policy with one run per seed, so each point is
the same statistic as the benchmark table (success: surviving fraction of all episodes;
tracking RMS: IQM over runs x scenarios, with its 95 % stratified-bootstrap interval).
Nothing of the training (its evaluation env, its best-agent choice) is used.

**Time to threshold.** The first checkpoint at which the policy (all its seeds together)
reaches a tracking RMS <= ``rms`` with a success >= ``success``; its env steps and the
median (and range) over seeds of their wall time at that checkpoint; and, per seed, the
first checkpoint where that seed alone meets both (its own success fraction and its IQM
over the scenarios).

``python evaluate.py curves RUNS... --out DIR`` writes ``curves.json``, ``curves.md``
(one compact table per policy, after a summary table when there are several) and
``curves.png``. A folder that holds a ``curves.json`` this command wrote (and no seed runs)
is read instead of evaluated (:func:`load_curves`), so curves evaluated separately, for
example one policy per core, are put side by side without evaluating them again.

**Files read.** Of each checkpoint agent folder, only ``agent.json`` and
``policy.safetensors`` are copied for the evaluation, each checked to be a regular file
inside it (:func:`~tether_gym_agents.files.folder_paths.copy_files_checked`): a symlink
leading out of it (to ``/dev/zero``, to another agent), a FIFO or a file over its size
cap is a ``ValueError`` naming it, before anything is evaluated; a checkpoint folder,
``checkpoints/`` or ``seed_K`` symlinked outside its run folder too.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..common.atomic_write import save_figure, write_text_atomic
from ..common.jsonio import loads_json
from ..files.folder_paths import copy_files_checked, file_inside
from ..files.run_folder import checkpoint_agents, seed_runs
from ..files.safe_format import AGENT_FILE, WEIGHTS_FILE
from .benchmark import MAX_SEEDS, EvalOptions, evaluate
from .registry import FILTERED, resolve_policy
from .stats import iqm, run_scores, success_counts

__all__ = ["Threshold", "learning_curves", "curve_points", "load_curves", "write_curves", "label",
           "DEFAULT_THRESHOLD"]

CURVES_FILE = "curves.json"
MAX_CURVE_RUNS = 10_000
"""Seed runs a read curve may record."""


@dataclass(frozen=True)
class Threshold:
    """What "reached" means: tracking RMS <= ``rms`` [rad] with success >= ``success`` [-]."""

    rms: float = 5.5e-3
    success: float = 0.99

    def met(self, rms: float | None, success: float | None) -> bool:
        """Whether a point (RMS, success) meets the threshold (None/NaN never does)."""
        return (rms is not None and success is not None and math.isfinite(rms)
                and rms <= self.rms and success >= self.success)


DEFAULT_THRESHOLD = Threshold()
"""5.5e-3 rad at >= 0.99 success: the fast-PPO target of the benchmark's issue tracker."""


def curve_points(folder: Path) -> list[tuple[int, list[tuple[Path, float]]]]:
    """``(steps, [(agent folder, wall time [s]) per seed])`` for the steps all seeds have.

    ``folder`` is a folder of ``seed_K`` run folders (or one run folder).
    """
    runs = seed_runs(folder) or [Path(folder)]
    per_run = []
    for run in runs:
        points = {}
        for steps, agent in checkpoint_agents(run):
            path = file_inside(agent, agent / AGENT_FILE)
            meta = loads_json(path.read_bytes(), path)
            training = meta.get("training") if isinstance(meta, dict) else None
            wall = training.get("wall_time_s") if isinstance(training, dict) else None
            points[steps] = (agent, _wall(wall))
        per_run.append(points)
    common = sorted(set.intersection(*(set(p) for p in per_run))) if per_run else []
    return [(steps, [p[steps] for p in per_run]) for steps in common]


def learning_curves(folder: Path, suite: str = "default", n_seeds: int = 10,
                    threshold: Threshold = DEFAULT_THRESHOLD, log=print,
                    filtered: bool = False) -> dict:
    """Evaluate every common checkpoint of a folder of seed runs on ``suite``.

    With ``filtered`` each checkpoint policy is scored behind the safety filter
    (``filtered:`` + the checkpoint, as ``python evaluate.py filtered:RUN`` scores a
    rate-mode agent), and the curve's policy is named ``filtered:FOLDER``.

    Returns ``{"policy", "suite", "seeds", "runs", "threshold", "points": [...],
    "reached": {...} or None, "per_seed": [...]}``; each point holds ``steps``,
    ``wall_time_s`` (per seed), ``success``, ``survived``, ``episodes``,
    ``tracking_rms`` (IQM), ``tracking_rms_ci95`` and the per-seed ``seed_success`` and
    ``seed_tracking_rms``.
    """
    points = curve_points(folder)
    if not points:
        raise ValueError(f"{folder}: no checkpoint agents (checkpoints/agent_<N>_steps/) "
                         "that every seed run has; train with this version of train.py")
    if filtered:  # the filtered form's own check (rate-mode runs only), before evaluating,
        # on a checkpoint where the user finds it rather than on the temporary copy below
        _ = resolve_policy(FILTERED + str(points[0][1][0][0])).env_kwargs
    out = []
    tmp = Path(tempfile.mkdtemp(prefix="tether_curves_"))
    try:
        for k, (steps, agents) in enumerate(points, 1):
            for i, (agent, _) in enumerate(agents):  # one policy, one run per seed
                copy_files_checked(agent, tmp / f"step_{steps}" / f"seed_{i}",
                                   (AGENT_FILE, WEIGHTS_FILE))
            name = (FILTERED if filtered else "") + str(tmp / f"step_{steps}")
            res = evaluate([name], suite, n_seeds, 0,
                           options=EvalOptions(out=None, plots=False, log=None))
            out.append(_point(res, steps, [w for _, w in agents]))
            if log:
                p = out[-1]
                log(f"  [{k}/{len(points)}] {steps} steps: success {p['success']:.3f}, "
                    f"tracking RMS {p['tracking_rms']:.3g} rad")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    n_runs = len(points[0][1])
    return {"policy": (FILTERED if filtered else "") + str(folder), "suite": suite,
            "seeds": n_seeds, "runs": n_runs,
            "points": out, **_at_threshold(out, n_runs, threshold)}


def _at_threshold(points: list[dict], n_runs: int, threshold: Threshold) -> dict:
    """The ``threshold``, ``reached`` and ``per_seed`` entries of a curve of ``points``."""
    return {"threshold": {"rms": threshold.rms, "success": threshold.success},
            "reached": _reached(points, threshold),
            "per_seed": [_seed_reached(points, i, threshold) for i in range(n_runs)]}


def load_curves(folder: Path, suite: str, n_seeds: int,
                threshold: Threshold = DEFAULT_THRESHOLD) -> list[dict]:
    """The curves in ``folder/curves.json``, their time to threshold recomputed.

    Raises ``ValueError`` if a curve was scored on another suite or number of seeds per
    scenario than asked (curves side by side must be the same statistic), or if the file
    is not a list of curves.
    """
    path = Path(folder) / CURVES_FILE
    curves = loads_json(file_inside(folder, path).read_bytes(), path)
    if not (isinstance(curves, list) and curves
            and all(isinstance(c, dict) and "points" in c for c in curves)):
        raise ValueError(f"{path} is not a curves.json written by evaluate.py curves")
    curves = [_checked_curve(c, f"{path}: curve {i}") for i, c in enumerate(curves)]
    for c in curves:
        if (c.get("suite"), c.get("seeds")) != (suite, n_seeds):
            raise ValueError(f"{path}: {c.get('policy')} was scored on suite "
                             f"{c.get('suite')!r} with {c.get('seeds')} seeds per scenario, "
                             f"not on {suite!r} with {n_seeds} (give --suite and --seeds)")
        c.update(_at_threshold(c["points"], c["runs"], threshold))
    return curves


def _wall(value) -> float:
    """A recorded wall time [s]; NaN when absent or not a finite number >= 0."""
    ok = (isinstance(value, (int, float)) and not isinstance(value, bool)
          and math.isfinite(value) and value >= 0)
    return float(value) if ok else math.nan


def _real(value, what: str, *, optional: bool = False) -> float:
    """A finite number (or, with ``optional``, JSON null: NaN, as it was written)."""
    if value is None and optional:
        return math.nan
    if (not isinstance(value, (int, float)) or isinstance(value, bool)
            or not math.isfinite(value)):
        raise ValueError(f"{what}={value!r}; allowed: a finite number"
                         + (" or null" if optional else ""))
    return float(value)


def _reals(values, n: int, what: str) -> list[float]:
    """``n`` numbers or nulls (NaN)."""
    if not isinstance(values, list) or len(values) != n:
        raise ValueError(f"{what}={values!r}; allowed: a list of {n} numbers or nulls "
                         "(one per seed run)")
    return [_real(v, f"{what}[{i}]", optional=True) for i, v in enumerate(values)]


def _checked_curve(curve: dict, what: str) -> dict:
    """A curve of curves.json with the types :func:`write_curves` wrote; NaN for null.

    ``write_curves`` writes NaN as null (strict JSON): a wall time a checkpoint did not
    record, an RMS of no surviving episode. Anything else out of place is a ValueError
    naming the curve and the key.
    """
    for key in ("policy", "suite"):
        if not isinstance(curve.get(key), str):
            raise ValueError(f"{what}: {key}={curve.get(key)!r}; allowed: a string")
    for key, high in (("seeds", MAX_SEEDS), ("runs", MAX_CURVE_RUNS)):
        value = curve.get(key)
        if not (isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= high):
            raise ValueError(f"{what}: {key}={value!r}; allowed: an integer in [1, {high}]")
    runs, points = curve["runs"], curve["points"]
    if not isinstance(points, list) or not points:
        raise ValueError(f"{what}: points={points!r}; allowed: a non-empty list")
    checked = []
    for k, point in enumerate(points):
        at = f"{what}: points[{k}]"
        if not isinstance(point, dict):
            raise ValueError(f"{at}={point!r}; allowed: a mapping")
        steps = point.get("steps")
        if not (isinstance(steps, int) and not isinstance(steps, bool) and steps >= 0):
            raise ValueError(f"{at}.steps={steps!r}; allowed: an integer >= 0")
        ci = point.get("tracking_rms_ci95")
        if ci is not None:
            if not isinstance(ci, list) or len(ci) != 2:
                raise ValueError(f"{at}.tracking_rms_ci95={ci!r}; allowed: null or "
                                 "[low, high]")
            ci = [_real(v, f"{at}.tracking_rms_ci95", optional=True) for v in ci]
        checked.append({
            **point, "steps": steps, "tracking_rms_ci95": ci,
            "success": _real(point.get("success"), f"{at}.success"),
            "tracking_rms": _real(point.get("tracking_rms"), f"{at}.tracking_rms",
                                  optional=True),
            **{key: _reals(point.get(key), runs, f"{at}.{key}")
               for key in ("wall_time_s", "seed_success", "seed_tracking_rms")}})
    return {**curve, "points": checked}


def label(curve: dict) -> str:
    """A curve's short name: its folder's name, ``filtered:`` kept in front."""
    policy = str(curve["policy"])
    prefix = FILTERED if policy.startswith(FILTERED) else ""
    return prefix + Path(policy[len(prefix):]).name


def _point(res: dict, steps: int, walls: list[float]) -> dict:
    (block,) = res["policies"].values()
    eps = res["episodes"]
    scenarios = list(res["scenarios"])
    runs = list(range(block["n_runs"]))
    rms = run_scores(eps, "tracking_rms", runs, scenarios)
    counts = success_counts(eps, runs, scenarios)
    seed_success = (counts.survived.sum(axis=1) / counts.episodes.sum(axis=1)).tolist()
    return {"steps": int(steps), "wall_time_s": walls, "success": block["success_rate"],
            "survived": block["survived"], "episodes": block["n_episodes"],
            "tracking_rms": block["tracking_rms"],
            "tracking_rms_ci95": block["ci95"]["tracking_rms"],
            "seed_success": seed_success, "seed_tracking_rms": [iqm(r) for r in rms]}


def _reached(points: list[dict], threshold: Threshold) -> dict | None:
    for p in points:
        if threshold.met(p["tracking_rms"], p["success"]):
            walls = [w for w in p["wall_time_s"] if math.isfinite(w)]
            return {"steps": p["steps"],
                    "wall_time_s_median": float(np.median(walls)) if walls else None,
                    "wall_time_s_range": [min(walls), max(walls)] if walls else None}
    return None


def _seed_reached(points: list[dict], i: int, threshold: Threshold) -> dict | None:
    for p in points:
        if threshold.met(p["seed_tracking_rms"][i], p["seed_success"][i]):
            return {"steps": p["steps"], "wall_time_s": p["wall_time_s"][i]}
    return None


def _fmt(x, spec: str) -> str:
    return "n/a" if x is None or not math.isfinite(x) else format(x, spec)


def _rms_text(point: dict) -> str:
    """A point's tracking RMS with its 95 % interval (when it has one)."""
    ci = point["tracking_rms_ci95"]
    ci_text = "" if ci is None else f" [{_fmt(ci[0], '.2e')}, {_fmt(ci[1], '.2e')}]"
    return f"{_fmt(point['tracking_rms'], '.2e')}{ci_text}"


def _alone(curves: dict) -> str:
    """How many seeds reach the threshold alone, and their median wall time."""
    seeds = [s for s in curves["per_seed"] if s is not None]
    return f"{len(seeds)} of {curves['runs']}" + (
        f", median {np.median([s['wall_time_s'] for s in seeds]) / 60:.1f} min" if seeds
        else "")


def _finite_median(values: list[float]) -> float:
    """The median of the finite ``values``; NaN (no warning) when there is none."""
    finite = [v for v in values if math.isfinite(v)]
    return float(np.median(finite)) if finite else math.nan


def _minutes(walls: list[float]) -> str:
    walls = [w for w in walls if math.isfinite(w)]
    if not walls:
        return "n/a"
    return f"{np.median(walls) / 60:.1f} ({min(walls) / 60:.1f}-{max(walls) / 60:.1f})"


def summary_markdown(all_curves: list[dict]) -> str:
    """One row per policy: its last checkpoint, and when (if) it reached the threshold."""
    th = all_curves[0]["threshold"]
    lines = [f"Time to tracking RMS <= {th['rms']:g} rad at success >= {th['success']:g} "
             f"(suite {all_curves[0]['suite']!r}, {all_curves[0]['seeds']} seeds per "
             "scenario and run)", "",
             "| policy | runs | env steps | wall time per run [min], median (range) | "
             "success | tracking RMS [rad] [95 % CI] | reached (all runs as one policy) | "
             "runs reaching it alone |", "|---|---|---|---|---|---|---|---|"]
    for c in all_curves:
        last = c["points"][-1]
        reached = c["reached"]
        when = ("not reached" if reached is None else
                f"{_fmt((reached['wall_time_s_median'] or math.nan) / 60, '.1f')} min, "
                f"{reached['steps']} steps")
        lines.append(f"| {label(c)} | {c['runs']} | {last['steps']} | "
                     f"{_minutes(last['wall_time_s'])} | {last['success']:.3f} "
                     f"({last['survived']}/{last['episodes']}) | "
                     f"{_rms_text(last)} | {when} | {_alone(c)} |")
    return "\n".join(lines)


def markdown(curves: dict) -> str:
    """A compact table of one policy's curve and its time to threshold."""
    th = curves["threshold"]
    lines = [f"{curves['policy']}: suite {curves['suite']!r}, {curves['runs']} runs x "
             f"{curves['seeds']} seeds per scenario", "",
             "| env steps | wall time [min], median (range) | success | tracking RMS [rad] "
             "[95 % CI] |", "|---|---|---|---|"]
    for p in curves["points"]:
        lines.append(f"| {p['steps']} | {_minutes(p['wall_time_s'])} | {p['success']:.3f} "
                     f"({p['survived']}/{p['episodes']}) | {_rms_text(p)} |")
    reached = curves["reached"]
    target = f"tracking RMS <= {th['rms']:g} rad at success >= {th['success']:g}"
    if reached is None:
        lines += ["", f"Not reached: {target}."]
    else:
        lo, hi = reached["wall_time_s_range"] or (math.nan, math.nan)
        lines += ["", f"Reached ({target}) at {reached['steps']} env steps, "
                      f"{_fmt((reached['wall_time_s_median'] or math.nan) / 60, '.1f')} min "
                      f"median wall time ({lo / 60:.1f}-{hi / 60:.1f} over the seeds)."]
    lines.append(f"Seeds reaching it alone: {_alone(curves)}.")
    return "\n".join(lines)


def write_curves(all_curves: list[dict], out: Path, log=print) -> list[Path]:
    """``curves.json``, ``curves.md`` and (with matplotlib) ``curves.png`` into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    from ..common.jsonio import to_jsonable

    paths = [out / CURVES_FILE, out / "curves.md"]
    write_text_atomic(paths[0], json.dumps(to_jsonable(all_curves), indent=1,
                                          allow_nan=False) + "\n")
    tables = [markdown(c) for c in all_curves]
    if len(all_curves) > 1:
        tables.insert(0, summary_markdown(all_curves))
    write_text_atomic(paths[1], "\n\n".join(tables) + "\n")
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        if log:
            log("  (curves.png skipped: matplotlib is missing; pip install \"matplotlib>=3.7\")")
        return paths
    fig = Figure(figsize=(12, 4.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax_steps, ax_wall, ax_succ = fig.subplots(1, 3)
    for k, c in enumerate(all_curves):
        pts = c["points"]
        steps = np.array([p["steps"] for p in pts], dtype=float)
        wall = np.array([_finite_median(p["wall_time_s"]) for p in pts]) / 60.0
        rms = np.array([np.nan if p["tracking_rms"] is None else p["tracking_rms"]
                        for p in pts])
        ci = np.array([(np.nan, np.nan) if p["tracking_rms_ci95"] is None
                       else p["tracking_rms_ci95"] for p in pts], dtype=float)
        name = label(c)
        for ax, x in ((ax_steps, steps), (ax_wall, wall)):
            ax.semilogy(x, rms, "-o", ms=3, color=f"C{k}", label=name)
            ax.fill_between(x, ci[:, 0], ci[:, 1], color=f"C{k}", alpha=0.25)
        ax_succ.plot(steps, [p["success"] for p in pts], "-o", ms=3, color=f"C{k}",
                     label=name)
    th = all_curves[0]["threshold"] if all_curves else {"rms": math.nan, "success": math.nan}
    for ax in (ax_steps, ax_wall):
        ax.axhline(th["rms"], color="grey", ls="--", lw=1)
        ax.set_ylabel("tracking RMS after orbit 1 [rad], IQM and 95 % CI")
        ax.grid(True, which="both", alpha=0.3)
    ax_steps.set_xlabel("env steps")
    ax_wall.set_xlabel("wall-clock time [min] (median over seeds)")
    ax_succ.axhline(th["success"], color="grey", ls="--", lw=1)
    ax_succ.set_xlabel("env steps")
    ax_succ.set_ylabel("success (surviving fraction of all episodes)")
    ax_succ.grid(True, alpha=0.3)
    ax_steps.legend(fontsize=8)
    fig.suptitle(f"Learning curves on suite {all_curves[0]['suite'] if all_curves else ''!r}"
                 " (checkpoints evaluated afterwards; dashed: the threshold)", fontsize=10)
    paths.append(out / "curves.png")
    save_figure(fig, paths[-1], dpi=100)
    return paths
