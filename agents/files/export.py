"""Share trained runs: copy their safe files, or convert a pickled run to a safe agent.

**What an export reads and writes.** :func:`export_runs` copies only regular files
inside the source folder, each under its size cap
(:func:`~.folder_paths.file_inside`; a symlink whose target stays inside is copied as
the file it points to). It refuses a file with more than one name (a **hard link**,
``st_nlink > 1``): the other name may be anywhere on the same file system (a secret of
the user's, linked into a folder received from someone else), and the folder's own files
are never hard links (``train.py`` writes each one new); copy the file (``cp``) to export
it. It writes only into folders it creates or that already are real folders inside the
destination: a symlinked ``DEST/eval`` (or any symlink below ``DEST``) is refused, never
written through, and a symlink at a destination file name is replaced, not followed.
A destination that is a file, or that is the source run folder itself, is refused.
Every check is made before anything is written.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from .folder_paths import FolderFileError, real_folder
from .pickled import load_pickled_run, run_features, run_hybrid
from .run_folder import (
    ARGS_FILE,
    BEST_MODEL_FILE,
    COMMAND_FILE,
    CONFIG_FILE,
    EVALUATIONS_FILE,
    FANOUT_LOG_FILE,
    FINAL_AGENT_DIR,
    LEARNING_CURVE_FILE,
    SEED_CURVES_FILE,
    TRAIN_INFO_FILE,
    read_train_info,
    seed_runs,
)
from .safe_format import (
    AGENT_FILE,
    WEIGHTS_FILE,
    AgentLoadError,
    checked_file,
    is_unit,
    save_agent,
)

__all__ = ["EXPORTED_FILES", "EXPORTED_FOLDER_FILES", "export_runs", "convert_run"]

EXPORTED_FILES = (AGENT_FILE, WEIGHTS_FILE, CONFIG_FILE, ARGS_FILE, COMMAND_FILE,
                  TRAIN_INFO_FILE, LEARNING_CURVE_FILE, EVALUATIONS_FILE)
"""What :func:`export_runs` copies of a run folder: the safe agent, how it was trained
and its learning curve (no pickles, checkpoints, TensorBoard files or logs)."""
EXPORTED_FOLDER_FILES = (SEED_CURVES_FILE, FANOUT_LOG_FILE)
"""What it copies of a folder of seed runs besides the runs."""


def export_runs(src, dest) -> list[Path]:
    """Copy the shareable files of a run folder, or of every ``seed_K`` run in a folder.

    Only :data:`EXPORTED_FILES` (and the folder's :data:`EXPORTED_FOLDER_FILES`) are
    copied; every run must hold a safe agent (``agent.json`` + ``policy.safetensors``).
    Every file to copy must be a regular file inside ``src`` under its size cap, with no
    other name (no hard link); a symlink whose target stays inside ``src`` is copied as
    the file it points to. Folders are written only where they are real folders below
    ``dest`` (module docstring); all is checked before anything is written, and a
    symlink at a destination name is replaced, never written through. Returns the run
    folders written.

    Raises
    ------
    AgentLoadError
        Naming a destination that is a file or the source folder itself, a run without
        a safe agent, a file that leads outside ``src``, is not a
        regular file (a symlink to ``/etc/passwd``, a FIFO), is over its cap or is a
        hard link, or a symlinked folder below ``dest``: nothing is copied then.
    """
    src, dest = Path(src), Path(dest)
    if (dest.exists() or dest.is_symlink()) and not dest.is_dir():
        raise AgentLoadError(f"export destination {dest} is a file, not a folder; give a new "
                             "or an existing folder")
    runs = seed_runs(src)
    pairs = [(run, dest / run.name) for run in runs] if runs else [(src, dest)]
    for run, out in pairs:
        if out.exists() and out.resolve() == run.resolve():
            raise AgentLoadError(f"export destination {out} is the run folder {run} itself; "
                                 "give another folder")
        for name in (AGENT_FILE, WEIGHTS_FILE):  # a FIFO there: named, not "no agent"
            if (run / name).exists() or (run / name).is_symlink():
                checked_file(src, run / name)
        if not is_unit(run):
            raise AgentLoadError(f"{run} holds no safe agent ({AGENT_FILE} + {WEIGHTS_FILE}); "
                                 "convert it first")
    copies = [(run / name, out / name) for run, out in pairs for name in EXPORTED_FILES]
    if runs:
        copies += [(src / name, dest / name) for name in EXPORTED_FOLDER_FILES]
    copies = [(a, b) for a, b in copies if a.exists() or a.is_symlink()]
    for source, target in copies:
        checked_file(src, source)
        if source.stat().st_nlink > 1:
            raise AgentLoadError(f"{source} is a hard link ({source.stat().st_nlink} names "
                                 "for one file, the others possibly outside the folder); "
                                 "export copies only files of their own: copy it (cp) "
                                 "first if it is yours to share")
        _real_parent(dest, target, make=False)
    for source, target in copies:
        _real_parent(dest, target, make=True)
        if target.is_symlink():
            target.unlink()
        shutil.copyfile(source, target)
        shutil.copystat(source, target)
    return [out for _, out in pairs]


def _real_parent(dest: Path, target: Path, make: bool) -> None:
    """Check (and with ``make`` create) ``target``'s folder: no symlink below ``dest``."""
    relative = target.parent.relative_to(dest)
    if not make:  # check only: each existing part must be a real folder
        folder = dest
        for part in relative.parts:
            folder = folder / part
            if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
                raise AgentLoadError(f"{folder} is a symlink or not a folder; export writes "
                                     "only into real folders inside the destination")
        return
    try:
        real_folder(dest, relative)
    except FolderFileError as exc:
        raise AgentLoadError(str(exc)) from None


def convert_run(path, out=None, allow_pickle: bool = False) -> Path:
    """Convert a stable-baselines3 run folder (pickles) to a safe agent folder.

    Parameters
    ----------
    path : path-like
        Run folder or model ``.zip`` inside one.
    out : path-like or None
        Agent folder to write (default: the run folder itself for ``best_model.zip``,
        as ``train.py`` writes it, else ``<run folder>/final_agent``).
    allow_pickle : bool
        Must be True: the conversion unpickles the files once.
    """
    run = load_pickled_run(path, allow_pickle=allow_pickle)
    cfg = run.config
    if out is None:
        out = (run.run_dir if run.model_path.name == BEST_MODEL_FILE
               else run.run_dir / FINAL_AGENT_DIR)
    train_info = read_train_info(run.run_dir)
    training = {"seed": cfg.get("seed", train_info.get("seed")),
                "num_timesteps": int(run.model.num_timesteps),
                "source": run.model_path.name,
                "command": train_info.get("command")}
    return save_agent(Path(out), run.model.policy, run.algo, run.norm,
                      env_id=cfg.get("env_id"), env_kwargs=cfg.get("env_kwargs"),
                      training=training, hybrid=run_hybrid(cfg), features=run_features(cfg))
