"""results.json and the printed tables of the benchmark.

``results.json`` is strict JSON (undefined values are ``null``, never ``NaN``)::

    meta        versions, command, git commit, threads, agent files with sha256
    suite, seeds, env_kwargs, scenarios {name: {description, env_kwargs, nominal}}
    cost_limit  the limit on an episode's mean cost per step [-] of ``over_limit``
    statistics  how the numbers below are computed
    policies    {name: {kind, n_runs, runs, n_episodes, survived, success_rate,
                        worst_scenario, worst_scenario_success, <metric>: IQM, ...,
                        over_limit_count, compute_ms_per_step, compute_ms_per_step_p99,
                        ci95: {metric: [lo, hi] or null},
                        probability_of_improvement: {metric: p or null},
                        failures: {slack, tumble, length}}}
    per_scenario {scenario: {policy: {<metric>: IQM over runs, over_limit_count,
                                      ci95: {<metric>: [lo, hi]}}}}
    episodes    [{policy, run, scenario, seed, <every metric>}, ...]

so that anyone can recompute the statistics from ``episodes``. Success is the raw
surviving fraction of all episodes everywhere (``success`` and ``success_rate`` of a
policy, ``success`` of a scenario), never an IQM: a failed episode is never trimmed
away (:mod:`.stats`). The same holds for ``over_limit``: the raw fraction of all
episodes whose mean cost per step (``cost_per_step``, an IQM like the other metrics)
exceeds ``cost_limit``, with ``over_limit_count`` such episodes of ``n_episodes``.
"""

from __future__ import annotations

import json
import math
import platform
import subprocess
from importlib import metadata
from pathlib import Path

from ..common.atomic_write import write_text_atomic
from ..common.jsonio import sha256_file, to_jsonable
from .metrics import COST_LIMIT, FAILURES, HIGHER_IS_BETTER, METRICS
from .stats import (
    BOOTSTRAP_SEED,
    N_BOOTSTRAP,
    iqm,
    probability_of_improvement,
    run_scores,
    stratified_bootstrap_ci,
    success_counts,
    success_rate_ci,
)

__all__ = ["build_results", "write_results", "markdown_tables", "to_jsonable", "run_meta",
           "TABLE_COLUMNS", "REFERENCE_POLICY"]

REFERENCE_POLICY = "smc"
"""The baseline of the probability of improvement."""
TABLE_COLUMNS = (
    ("success", "success rate"),
    ("tracking_rms", "tracking RMS [rad]"),
    ("final_error", "last-orbit max err [rad]"),
    ("converge_orbits", "converge [orbits]"),
    ("min_tension", "min T^ [-]"),
    ("reel_effort", "reel effort [-]"),
    ("reel_excursion", "reel excursion [-]"),
    ("chattering", "chattering [-]"),
    ("cost_per_step", "cost/step [-]"),
    ("over_limit", "over cost limit"),
)
PACKAGES = ("tether_gym", "numpy", "scipy", "gymnasium", "numba", "torch",
            "stable-baselines3", "matplotlib")


def agent_files(path: Path) -> dict:
    """``{file name: sha256}`` of an agent: the file itself, or a run folder's files."""
    path = Path(path)
    files = [path] if path.is_file() else sorted(p for p in path.iterdir() if p.is_file())
    return {p.name: sha256_file(p) for p in files}


def display_path(path) -> str:
    """``path`` relative to the repository (or working directory) when inside it."""
    path = Path(path).resolve()
    for root in (Path(__file__).resolve().parents[2], Path.cwd()):
        try:
            return str(path.relative_to(root))
        except ValueError:
            continue
    return str(path)


def _git_commit() -> dict | None:
    root = Path(__file__).resolve().parents[2]
    if not (root / ".git").exists():
        return None
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], check=True,
                                capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain",
                                "--untracked-files=no"], check=True, capture_output=True,
                               text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return {"commit": commit, "dirty": bool(dirty)}


def run_meta(specs, command: str | None, torch_threads: int | None) -> dict:
    """The ``meta`` block: versions, command, git commit, threads, agent files."""
    versions: dict[str, str | None] = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    threads: dict[str, int | None] = {"torch": None, "numba": None}
    if any(s.kind.value != "baseline" for s in specs):
        import torch

        threads["torch"] = int(torch.get_num_threads())
    # numba's configured count: numba.get_num_threads() would start its OpenMP pool,
    # which resets the OpenMP thread count torch runs with (and spins while idle)
    import numba

    threads["numba"] = int(numba.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]
    git = _git_commit()
    return {
        "versions": versions,
        "command": command,
        "git_commit": git["commit"] if git else None,
        "git_dirty": git["dirty"] if git else None,
        "platform": platform.platform(),
        "threads": threads,
        "torch_threads_requested": torch_threads,
        "agents": {s.name: [{"path": display_path(p), "files": agent_files(p)}
                            for p in s.runs]
                   for s in specs if any(p is not None for p in s.runs)},
    }


STATISTICS = {
    "point_estimate": "interquartile mean (scipy.stats.trim_mean, 25 % cut at each "
                      "end) over runs x scenarios of each run's mean over its "
                      "episodes; undefined episode values left out; success excepted",
    "success": "success and success_rate: surviving episodes / all episodes (raw, "
               "nothing trimmed); worst_scenario_success: the same for the scenario "
               "where it is lowest; per scenario: over all runs' episodes; ci95 of "
               "success: percentile interval over the same stratified bootstrap of "
               "runs",
    "cost": "cost_per_step: an episode's mean info['cost'] over its control steps (a "
            "failed episode's up to and including the failing one), IQM as the other "
            "metrics; over_limit: episodes with cost_per_step > cost_limit / all "
            "episodes (raw, nothing trimmed, as success; over_limit_count: their "
            "number), its ci95 over the same stratified bootstrap of runs",
    "compute_ms_per_step": "median (and p99) wall time of one predict call on one "
                           "observation, over the control steps of one episode "
                           "(first scenario, first run, first seed), torch on the "
                           "requested threads",
    "ci95": f"95 % percentile interval of the IQM over {N_BOOTSTRAP} stratified "
            "bootstrap resamples (runs drawn with replacement within each "
            f"scenario, seed {BOOTSTRAP_SEED}); null with fewer than 2 runs",
    "probability_of_improvement": f"P(policy improves on {REFERENCE_POLICY}) per "
                                  "scenario over all pairs of runs (Mann-Whitney U / "
                                  "(n_x n_y), ties 1/2), averaged over scenarios; "
                                  "null if smc was not evaluated",
    "higher_is_better": sorted(HIGHER_IS_BETTER),
    "reference": "Agarwal et al. (2021), Deep RL at the Edge of the Statistical "
                 "Precipice, NeurIPS",
}
"""How the numbers of results.json are computed (its ``statistics`` block)."""


def _policy_block(spec, eps: list[dict], scores: dict, reference: dict | None,
                  scenario_names: list) -> dict:
    """One policy's entry of ``policies``: kind, runs, IQMs, intervals, P(improvement)."""
    block = {"kind": spec.kind.value, "n_runs": spec.n_runs,
             "runs": [None if p is None else display_path(p) for p in spec.runs],
             "env_kwargs": spec.env_kwargs, "n_episodes": len(eps)}
    counts = success_counts(eps, list(range(spec.n_runs)), scenario_names)
    worst, worst_rate = counts.worst(scenario_names)
    block.update(survived=int(counts.survived.sum()), success_rate=counts.rate,
                 worst_scenario=worst, worst_scenario_success=worst_rate)
    for m in METRICS:
        block[m] = iqm(scores[m])
    block["success"] = counts.rate
    block["ci95"] = {m: stratified_bootstrap_ci(scores[m]) for m in METRICS}
    block["ci95"]["success"] = success_rate_ci(counts)
    _over_limit(block, eps, spec.n_runs, scenario_names)
    block["probability_of_improvement"] = {
        m: (None if reference is None else probability_of_improvement(
            scores[m], reference[m], m in HIGHER_IS_BETTER)) for m in METRICS}
    block["failures"] = {f: int(sum(e[f] for e in eps)) for f in FAILURES}
    if eps and all("filter_rate" in e for e in eps):  # a safety filter's interventions
        block["filter_rate"] = iqm(run_scores(eps, "filter_rate", list(range(spec.n_runs)),
                                              scenario_names))
    return block


def _scenario_block(scores: dict, eps: list[dict], n_runs: int, scenario: str,
                    j: int) -> dict:
    """One policy on one scenario: IQM over runs (success: raw fraction), intervals."""
    counts = success_counts([e for e in eps if e["scenario"] == scenario],
                            list(range(n_runs)), [scenario])
    ci95 = {m: stratified_bootstrap_ci(scores[m][:, j:j + 1]) for m in METRICS}
    ci95["success"] = success_rate_ci(counts)
    block: dict = {m: iqm(scores[m][:, j]) for m in METRICS}
    block.update(success=counts.rate, ci95=ci95)
    _over_limit(block, [e for e in eps if e["scenario"] == scenario], n_runs, [scenario])
    return block


def _over_limit(block: dict, eps: list[dict], n_runs: int, scenario_names: list) -> None:
    """Set ``over_limit`` (raw fraction of ``eps``), its count and interval in ``block``.

    Like success: episodes over the cost limit / all episodes, never an IQM; NaN (and a
    null count) when no episode has a cost.
    """
    if not any(_finite(e.get("over_limit")) for e in eps):
        block.update(over_limit=math.nan, over_limit_count=None)
        block["ci95"]["over_limit"] = None
        return
    counts = success_counts(eps, list(range(n_runs)), scenario_names, "over_limit")
    block.update(over_limit=counts.rate, over_limit_count=int(counts.survived.sum()))
    block["ci95"]["over_limit"] = success_rate_ci(counts)


def _finite(x) -> bool:
    return x is not None and math.isfinite(x)


def build_results(specs, settings, seeds: list[int], episodes: list[dict], env_kwargs: dict,
                  suite: str, command: str | None = None,
                  torch_threads: int | None = None, compute: dict | None = None) -> dict:
    """The results dict (module docstring) from the per-episode records.

    ``compute`` maps a policy name to its ``(median, p99)`` wall time per control step
    [ms] (:func:`.benchmark.compute_cost`); a policy without an entry gets null.
    """
    scenario_names = [st.scenario.name for st in settings]
    by_policy = {s.name: [e for e in episodes if e["policy"] == s.name] for s in specs}
    scores = {s.name: {m: run_scores(by_policy[s.name], m, list(range(s.n_runs)),
                                     scenario_names) for m in METRICS} for s in specs}
    reference = scores.get(REFERENCE_POLICY)
    policies = {spec.name: _policy_block(spec, by_policy[spec.name], scores[spec.name],
                                         reference, scenario_names) for spec in specs}
    for name, block in policies.items():
        median, p99 = (compute or {}).get(name, (None, None))
        block.update(compute_ms_per_step=median, compute_ms_per_step_p99=p99)
    per_scenario = {sc: {spec.name: _scenario_block(scores[spec.name], by_policy[spec.name],
                                                   spec.n_runs, sc, j)
                         for spec in specs}
                    for j, sc in enumerate(scenario_names)}
    return {
        "meta": run_meta(specs, command, torch_threads),
        "suite": str(suite),
        "seeds": list(seeds),
        "env_kwargs": env_kwargs,
        "scenarios": {st.scenario.name: {"description": st.scenario.description,
                                         "env_kwargs": st.env_kwargs,
                                         "nominal": st.scenario.nominal}
                      for st in settings},
        "cost_limit": COST_LIMIT,
        "statistics": dict(STATISTICS),
        "policies": policies,
        "per_scenario": per_scenario,
        "episodes": episodes,
    }


def write_results(results: dict, path: Path) -> None:
    """Write ``results`` as strict JSON (no NaN tokens) to ``path``."""
    text = json.dumps(to_jsonable(results), indent=1, allow_nan=False)
    write_text_atomic(Path(path), text + "\n")  # never through a link or FIFO there


def _num(x) -> str:
    if x is None or not math.isfinite(x):
        return "n/a"
    if x == 0 or 0.01 <= abs(x) < 1e4:
        return f"{x:.3f}"
    return f"{x:.2g}"


def _worst(block: dict) -> str:
    """``fraction (scenario)`` of the worst scenario's surviving episodes."""
    rate = block.get("worst_scenario_success")
    if rate is None or not math.isfinite(rate):
        return "n/a"
    return f"{rate:.2f} ({block['worst_scenario']})"


def _ms(block: dict) -> str:
    """Median compute time per control step [ms] (n/a when it was not measured)."""
    ms = block.get("compute_ms_per_step")
    return "n/a" if ms is None or not math.isfinite(ms) else f"{ms:.2g}"


_COUNTED = {"success": "survived", "over_limit": "over_limit_count"}
"""Raw-fraction columns and the key of their episode count (shown as ``(count/all)``)."""


def _cell(block: dict, metric: str) -> str:
    text = _num(block[metric])
    count = block.get(_COUNTED.get(metric, ""))
    if count is not None and "n_episodes" in block and _finite(block[metric]):
        text += f" ({count}/{block['n_episodes']})"
    ci = block["ci95"].get(metric)
    if ci is not None:
        text += f" [{_num(ci[0])}, {_num(ci[1])}]"
    return text


def markdown_tables(results: dict) -> str:
    """The printed tables.

    IQM [95 % CI] per policy, the probability of improvement over smc, and a
    per-scenario table.
    """
    pols = results["policies"]
    names = list(pols)
    limit = results.get("cost_limit", COST_LIMIT)
    lines = ["Success: surviving fraction of all episodes (survived/episodes); over cost "
             f"limit: fraction of all episodes whose mean cost per step > {limit:g} "
             "(over/episodes); other metrics: IQM over training runs x scenarios; [95 % "
             "stratified-bootstrap CI over runs, 2+ runs]", "",
             "| policy | kind | runs | " + " | ".join(t for _, t in TABLE_COLUMNS)
             + " | worst scenario | failures slack/tumble/length | ms/step |",
             "|---" * (len(TABLE_COLUMNS) + 6) + "|"]
    for name, block in pols.items():
        counts = "/".join(str(block["failures"][f]) for f in FAILURES)
        lines.append(f"| {name} | {block['kind']} | {block['n_runs']} | "
                     + " | ".join(_cell(block, m) for m, _ in TABLE_COLUMNS)
                     + f" | {_worst(block)} | {counts} | {_ms(block)} |")
    if any(v is not None for b in pols.values() for v in b["probability_of_improvement"].values()):
        lines += ["", f"Probability of improvement over {REFERENCE_POLICY} "
                      "(per scenario over pairs of runs, averaged over scenarios)", "",
                  "| policy | " + " | ".join(t for _, t in TABLE_COLUMNS) + " |",
                  "|---" * (len(TABLE_COLUMNS) + 1) + "|"]
        for name, block in pols.items():
            poi = block["probability_of_improvement"]
            lines.append(f"| {name} | " + " | ".join(
                "n/a" if poi[m] is None else f"{poi[m]:.2f}" for m, _ in TABLE_COLUMNS) + " |")
    lines += ["", "Per scenario: success (surviving fraction of the runs' episodes) / "
                  "tracking RMS after orbit 1 [rad] (IQM over runs) [95 % bootstrap CI over "
                  "runs, 2+ runs]", "",
              "| scenario | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
    for sc, per in results["per_scenario"].items():
        cells = []
        for p in names:
            cells.append(_scenario_cell(per[p], "success", "{:.2f}") + " / "
                         + _scenario_cell(per[p], "tracking_rms", "{:.2e}"))
        lines.append(f"| {sc} | " + " | ".join(cells) + " |")
    lines += _scenario_cost_table(results, names, limit)
    return "\n".join(lines)


def _scenario_cost_table(results: dict, names: list, limit: float) -> list[str]:
    """Lines of the per-scenario table of cost/step (IQM) / over cost limit (fraction)."""
    lines = ["", "Per scenario: cost/step [-] (IQM over runs) / over cost limit (fraction of "
                 f"the runs' episodes with mean cost per step > {limit:g}) [95 % bootstrap "
                 "CI over runs, 2+ runs]", "",
             "| scenario | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
    for sc, per in results["per_scenario"].items():
        cells = [_scenario_cell(per[p], "cost_per_step", "{:.3g}") + " / "
                 + _scenario_cell(per[p], "over_limit", "{:.2f}") for p in names]
        lines.append(f"| {sc} | " + " | ".join(cells) + " |")
    return lines


def _scenario_cell(block: dict, metric: str, fmt: str) -> str:
    """``value [lo, hi]`` of one policy on one scenario (interval only with 2+ runs)."""
    value = block.get(metric)
    if value is None or not math.isfinite(value):
        return "n/a"
    ci = block.get("ci95", {}).get(metric)
    return fmt.format(value) + ("" if ci is None else
                                " [" + fmt.format(ci[0]) + ", " + fmt.format(ci[1]) + "]")
