"""Hostile-input sweep of issue 33: every surface a user passes, each input in a subprocess.

``python experiments/issue33/sweep.py --jobs 2 [--out results.csv] [--only SURFACE]
[--ids PATTERN,...]`` builds two tiny runs with ``train.py`` (the fixtures every agent and
run-folder input copies), then runs each input of :mod:`hostile_inputs` with its own
temporary folder as the working directory, ``timeout`` s of wall time, an address-space
limit (``--memory-gib``, RLIMIT_AS) and one thread per library, and classes the outcome
(:func:`classify`):

===========  ===========================================================================
clear        refused: nonzero exit, no traceback, a message of at most 3 lines on stderr
unclear      refused, no traceback, but the message is empty or longer than 3 lines
traceback    "Traceback (most recent call last)" in the output
accepted     an ``invalid`` input that exited 0, or any input that did harm (``check``)
hang         ran past the timeout, was killed by a signal, or hit MemoryError/bad_alloc
ran          a ``valid``/``warn``/``any`` input that exited 0 (``warn``: with a warning)
refused      a ``valid``/``warn`` input that was refused (nonzero exit)
silent       a ``warn`` input that ran without a warning
===========  ===========================================================================

``clear`` is also the class of an ``any`` input that was refused. The CSV has one row per
input (id, surface, expect, input, class, seconds, exit, names_input, usage, message); the
totals and the list of inputs classed traceback/accepted/hang (and unclear/refused/silent) are
printed at the end.
"""

from __future__ import annotations

import argparse
import csv
import fnmatch
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import fixtures as fx  # noqa: E402
import hostile_inputs  # noqa: E402

CLASSES = ("clear", "unclear", "traceback", "accepted", "hang", "ran", "refused", "silent")
BAD = ("traceback", "accepted", "hang")
"""The classes issue 33 requires to be zero."""
MAX_MESSAGE_LINES = 3
_WARNING_LINE = re.compile(r"^\S.*:\d+: \w*Warning: ")
_GYM_WARN = re.compile(r"^(\x1b\[\d+m)?WARN: ")


def message_lines(stderr: str) -> list[str]:
    """The lines of an error message: stderr's nonblank lines, less Python warnings.

    A warning (``file:line: XWarning: text``) and the source line printed under it
    (indented) and gymnasium's ``WARN:`` lines are left out, as are blank lines and
    argparse's usage block before its ``prog: error: ...`` line (:func:`argparse_usage`
    counts those); everything else counts (Ray's log lines too).
    """
    lines = stderr.splitlines()
    out: list[str] = []
    skip_indented = False
    in_usage = False
    for line in lines:
        if not line.strip():
            continue
        if line.startswith("usage: ") and any(": error: " in ln for ln in lines):
            in_usage = True  # argparse's usage block before its one error line
        if in_usage:
            if ": error: " not in line:
                continue
            in_usage = False
        if _WARNING_LINE.match(line):
            skip_indented = True
            continue
        if _GYM_WARN.match(line):  # gymnasium's logger.warn
            continue
        if skip_indented and line.startswith((" ", "\t")):
            continue
        skip_indented = False
        out.append(line.rstrip())
    return out


def argparse_usage(stderr: str) -> bool:
    """Whether stderr holds argparse's usage block before an error line."""
    return stderr.startswith("usage: ") and ": error: " in stderr


def has_warning(stdout: str, stderr: str) -> bool:
    text = stdout + stderr
    return bool(re.search(r"Warning\b|\bwarning\b|warn:", text))


def classify(expect: str, rc: int | None, stdout: str, stderr: str, timed_out: bool,
             harm: str | None = None) -> tuple[str, str]:
    """(class, one-line message) of an outcome; see the module docstring.

    ``rc`` is the exit status (negative: killed by that signal; None with ``timed_out``).
    """
    text = stdout + "\n" + stderr
    if timed_out:
        return "hang", "no exit before the timeout"
    if "MemoryError" in text or "bad_alloc" in text or "Cannot allocate memory" in text:
        line = next((ln for ln in reversed(text.splitlines())
                     if "MemoryError" in ln or "bad_alloc" in ln or "allocate" in ln), "")
        return "hang", f"allocation failed: {line.strip()[:200]}"
    if rc is not None and rc < 0:
        return "hang", f"killed by signal {signal.Signals(-rc).name}"
    if "Traceback (most recent call last)" in text:
        tail = [ln for ln in text.splitlines() if ln.strip()]
        exc = next((ln for ln in reversed(tail) if re.match(r"^[\w.]+(Error|Exception|Exit|"
                                                             r"Interrupt)\b", ln)), tail[-1])
        return "traceback", exc.strip()[:300]
    lines = message_lines(stderr)
    first = (lines[0] if lines else (stdout.strip().splitlines() or [""])[-1])[:300]
    if harm:
        return "accepted", f"harm: {harm}"
    if rc == 0:
        if expect == "invalid":
            return "accepted", first or "(exit 0, nothing on stderr)"
        if expect == "warn" and not has_warning(stdout, stderr):
            return "silent", "ran without a warning"
        return "ran", first
    if expect in ("valid", "warn"):
        return "refused", first
    if 1 <= len(lines) <= MAX_MESSAGE_LINES:
        return "clear", first
    return "unclear", (f"{len(lines)} lines: " + first) if lines else "(no message)"


# --------------------------------------------------------------------------- #
def _limits(memory_bytes: int):
    def apply():
        os.setsid()
        resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    return apply


def child_env() -> dict:
    env = dict(os.environ)
    env.pop("RAY_ADDRESS", None)
    env.update(OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1", MKL_NUM_THREADS="1",
               OPENBLAS_NUM_THREADS="1", MPLBACKEND="Agg", RAY_USAGE_STATS_ENABLED="0",
               PYTHONDONTWRITEBYTECODE="1")
    return env


def fill(arg: str, tmp: Path, fix: Path) -> str:
    return (arg.replace("{py}", sys.executable).replace("{repo}", str(fx.REPO))
            .replace("{tmp}", str(tmp)).replace("{fix}", str(fix)))


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def run_one(inp, fix: Path, timeout: float, memory_bytes: int, keep: bool = False) -> dict:
    tmp = Path(tempfile.mkdtemp(prefix="i33_"))
    row = {"id": inp.id, "surface": inp.surface, "expect": inp.expect, "input": inp.input}
    try:
        if inp.setup is not None:
            inp.setup(tmp, fix)
        argv = [fill(a, tmp, fix) for a in inp.argv]
        work = tmp / "cwd"
        work.mkdir()
        start = time.monotonic()
        proc = subprocess.Popen(argv, cwd=work, env=child_env(), stdin=subprocess.DEVNULL,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                preexec_fn=_limits(memory_bytes))
        timed_out = False
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            timed_out = True
            _kill_group(proc)
            out, err = proc.communicate()
        _kill_group(proc)  # anything the input left behind (Ray, workers)
        seconds = time.monotonic() - start
        stdout = out.decode(errors="replace")
        stderr = err.decode(errors="replace")
        harm = inp.check(tmp, fix) if inp.check is not None else None
        cls, msg = classify(inp.expect, None if timed_out else proc.returncode, stdout,
                            stderr, timed_out, harm)
        names = "-"
        if inp.names and cls in ("clear", "unclear"):
            names = "yes" if fill(inp.names, tmp, fix) in stderr else "no"
        row.update({"class": cls, "seconds": f"{seconds:.1f}",
                    "exit": "timeout" if timed_out else proc.returncode,
                    "names_input": names,
                    "usage": "yes" if argparse_usage(stderr) else "no",
                    "message": " ".join(msg.split())})
    except Exception as exc:  # a defect of the harness, reported as such
        row.update({"class": "harness-error", "seconds": "0", "exit": "",
                    "names_input": "-", "usage": "no",
                    "message": f"{type(exc).__name__}: {exc}"[:300]})
    finally:
        if not keep:
            _make_removable(tmp)
            shutil.rmtree(tmp, ignore_errors=True)
    return row


def _make_removable(root: Path) -> None:
    for dirpath, dirs, files in os.walk(root):
        for name in dirs + files:
            p = Path(dirpath) / name
            if not p.is_symlink():
                try:
                    p.chmod(0o700)
                except OSError:
                    pass


def select(inputs, only: list[str] | None, ids: list[str] | None):
    if only:
        groups = {name: {x.surface for x in make()}
                  for name, make in hostile_inputs.SURFACES.items() if name in only}
        wanted = set(only).union(*groups.values())
        inputs = [x for x in inputs if x.surface in wanted]
    if ids:
        inputs = [x for x in inputs if any(fnmatch.fnmatch(x.id, p) for p in ids)]
    return inputs


FIELDS = ["id", "surface", "expect", "input", "class", "seconds", "exit", "names_input",
          "usage", "message"]


def totals(rows) -> dict:
    out = {c: 0 for c in CLASSES}
    for r in rows:
        out[r["class"]] = out.get(r["class"], 0) + 1
    return out


def report(rows) -> str:
    """Totals per class and surface, then every input not classed clear or ran."""
    surfaces = sorted({r["surface"] for r in rows})
    classes = [c for c in CLASSES if any(r["class"] == c for r in rows)]
    classes += sorted({r["class"] for r in rows} - set(classes))
    head = "| surface | inputs | " + " | ".join(classes) + " |"
    lines = [head, "|" + "---|" * (len(classes) + 2)]
    for s in surfaces + ["all"]:
        sel = [r for r in rows if s == "all" or r["surface"] == s]
        counts = totals(sel)
        name = "**all**" if s == "all" else s
        lines.append(f"| {name} | {len(sel)} | "
                     + " | ".join(str(counts.get(c, 0)) for c in classes) + " |")
    lines.append("")
    flagged = [r for r in rows if r["class"] not in ("clear", "ran")]
    order = {c: i for i, c in enumerate(("traceback", "accepted", "hang", "harness-error",
                                         "refused", "silent", "unclear"))}
    flagged.sort(key=lambda r: (order.get(r["class"], 9), r["surface"], r["id"]))
    lines.append(f"inputs not classed clear/ran: {len(flagged)}")
    for r in flagged:
        lines.append(f"  {r['class']:<9} {r['surface']:<13} {r['id']}  [{r['input'][:70]}]  "
                     f"{r['seconds']} s: {r['message'][:220]}")
    usage = [r for r in rows if r.get("usage") == "yes"]
    if usage:
        lines.append(f"refusals printed after argparse's usage block (not counted as message "
                     f"lines): {len(usage)}")
    vague = [r for r in rows if r["names_input"] == "no"]
    if vague:
        lines.append(f"refusals that do not name the file given: {len(vague)}")
        lines += [f"  {r['id']}: {r['message'][:160]}" for r in vague]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=1, help="inputs run at once (default 1)")
    parser.add_argument("--out", type=Path, default=HERE / "results.csv",
                        help="CSV of the outcomes (default experiments/issue33/results.csv)")
    parser.add_argument("--only", nargs="+", metavar="SURFACE",
                        help="run only these surfaces (a surface of the CSV, or a group: "
                             f"{', '.join(hostile_inputs.SURFACES)})")
    parser.add_argument("--ids", type=lambda s: s.split(","), default=None,
                        help="comma-separated ids or glob patterns (e.g. 'agent.w.*')")
    parser.add_argument("--timeout", type=float, default=60.0,
                        help="seconds before an input counts as a hang (default 60)")
    parser.add_argument("--memory-gib", type=float, default=6.0,
                        help="address-space limit of each input [GiB] (default 6)")
    parser.add_argument("--fixtures", type=Path, default=None,
                        help="folder of the tiny runs (default: a new temporary folder; "
                             "an existing one is reused)")
    parser.add_argument("--report", type=Path, default=None,
                        help="also write the totals and the list of inputs not classed "
                             "clear/ran to this file")
    parser.add_argument("--list", action="store_true", help="list the inputs and exit")
    parser.add_argument("--keep", action="store_true", help="keep each input's folder")
    args = parser.parse_args(argv)
    inputs = select(hostile_inputs.all_inputs(), args.only, args.ids)
    if args.list:
        for x in inputs:
            print(f"{x.id:<40} {x.surface:<13} {x.expect:<8} {x.input[:80]}")
        print(f"{len(inputs)} inputs")
        return 0
    if not inputs:
        parser.error("no input matches --only/--ids")
    t0 = time.monotonic()
    fix = args.fixtures or Path(tempfile.mkdtemp(prefix="i33_fixtures_"))
    print(f"fixtures in {fix} ...", flush=True)
    fx.build_fixtures(fix, child_env())
    print(f"fixtures ready ({time.monotonic() - t0:.0f} s); {len(inputs)} inputs, "
          f"{args.jobs} at a time, timeout {args.timeout:.0f} s", flush=True)
    memory = int(args.memory_gib * 2 ** 30)
    rows: list[dict] = []
    lock = threading.Lock()
    args.out.parent.mkdir(parents=True, exist_ok=True)

    with open(args.out, "w", newline="") as f:  # rows as they come; sorted at the end
        csv.DictWriter(f, fieldnames=FIELDS).writeheader()

    def work(inp):
        row = run_one(inp, fix, args.timeout, memory, args.keep)
        with lock:
            rows.append(row)
            with open(args.out, "a", newline="") as f:
                csv.DictWriter(f, fieldnames=FIELDS).writerow(row)
            print(f"[{len(rows):>3}/{len(inputs)}] {row['class']:<9} {row['seconds']:>5} s "
                  f"{inp.id}: {row['message'][:100]}", flush=True)
        return row

    with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        list(pool.map(work, inputs))
    order = {x.id: i for i, x in enumerate(inputs)}
    rows.sort(key=lambda r: order[r["id"]])
    with open(args.out, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    if args.fixtures is None:
        shutil.rmtree(fix, ignore_errors=True)
    counts = totals(rows)
    summary = (f"{len(rows)} inputs in {time.monotonic() - t0:.0f} s ({args.jobs} at a time, "
               f"timeout {args.timeout:.0f} s): "
               + ", ".join(f"{c} {n}" for c, n in counts.items() if n))
    text = report(rows) + "\n\n" + summary
    print()
    print(text)
    if args.report is not None:
        args.report.write_text(text + "\n")
    print(f"results: {args.out}")
    return 1 if any(counts.get(c) for c in BAD) else 0


if __name__ == "__main__":
    raise SystemExit(main())
