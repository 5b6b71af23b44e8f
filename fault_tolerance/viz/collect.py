"""Which runs a replay shows: one run, or the run folders one command wrote, side by side.

``simulate --out out/fig2`` writes one folder per algorithm (``out/fig2/jvja``, ...); ``reproduce``
writes one per case and algorithm. :func:`run_folders` finds the runs in a folder (the folder itself
when it holds ``run.npz``, else its sub-folders that do); :func:`collect_runs` turns what the user
gave (a Run, a folder, a list or a dict of runs, an array of joint positions) into labelled items.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.simulation.run import Run


def run_folders(folder: str | Path) -> list[Path]:
    """The saved runs under ``folder``: itself if it holds ``run.npz``, else its run sub-folders.

    Example:
        >>> run_folders("out/fig2")  # doctest: +SKIP
        [PosixPath('out/fig2/jvja'), PosixPath('out/fig2/lnva'), PosixPath('out/fig2/mda')]
    """
    folder = Path(folder)
    if (folder / "run.npz").is_file() or folder.suffix == ".npz":
        return [folder]
    if not folder.is_dir():
        raise InvalidInput(f"{folder}: no saved run here (expected a folder with run.npz)")
    found = sorted(p for p in folder.iterdir() if p.is_dir() and (p / "run.npz").is_file())
    if not found:
        raise InvalidInput(
            f"{folder}: no saved run here (expected run.npz in it or in its sub-folders)"
        )
    return found


def collect_runs(run) -> list[tuple[str, object]]:
    """``[(label, run), ...]`` for a Run, a folder (of runs), a list / dict of those, or an array."""
    if isinstance(run, (str, Path)):
        folders = run_folders(run)
        if len(folders) == 1:
            loaded = Run.load(folders[0])
            return [(str(loaded.meta.get("algorithm") or folders[0].name), loaded)]
        items: list[tuple[str, object]] = [(p.name, Run.load(p)) for p in folders]
    elif isinstance(run, Run):
        return [(str(run.meta.get("algorithm") or "run"), run)]
    elif isinstance(run, Mapping):
        items = [(str(k), Run.load(v) if isinstance(v, (str, Path)) else v) for k, v in run.items()]
    elif isinstance(run, list) and run and all(isinstance(r, (Run, str, Path)) for r in run):
        items = []
        for r in run:
            if isinstance(r, (str, Path)):
                items.append((Path(r).name, Run.load(r)))
            else:
                items.append((str(r.meta.get("algorithm") or "run"), r))
    else:  # an array of joint positions or a pair (t, q): one motion, checked by the scene
        return [("run", run)]
    if not items:
        raise InvalidInput("no runs to replay")
    labels = [label for label, _ in items]
    if len(set(labels)) < len(labels):  # e.g. two lock runs of one algorithm
        items = [(f"{label} {i + 1}", r) for i, (label, r) in enumerate(items)]
    joints = {tuple(r.meta.get("joint_names") or ()) for _, r in items if isinstance(r, Run)}
    if len(joints) > 1:
        raise InvalidInput(
            "these runs were made with different arms (joints "
            + "; ".join(str(list(j)) for j in sorted(joints))
            + "); replay them one at a time"
        )
    return items


def describe_runs(folder: str | Path) -> list[str]:
    """One line per run under ``folder``: name, robot, algorithm, duration, lock (for listings)."""
    lines = []
    for p in run_folders(folder):
        try:
            with np.load(p / "run.npz", allow_pickle=False) as z:
                import json

                meta = json.loads(str(z["meta"]))
        except (OSError, ValueError, KeyError) as err:
            lines.append(f"{p}: unreadable ({err})")
            continue
        lock = meta.get("lock")
        what = f", {lock['joint']} locks at {lock['time']:.3g} s" if lock else ""
        lines.append(
            f"{p}: {meta.get('robot', '?')}, {meta.get('algorithm', '?')}, "
            f"{meta.get('duration', '?')} s{what}"
        )
    return lines
