"""The dataset directory's layout, its lock and the clean-up of an interrupted run.

::

    <out>/manifest.json                                   what the folder holds (simspad.io.manifest)
    <out>/.simspad.lock                                   held by the one run writing the folder
    <out>/renders/<sequence>[_x<k>]-<render hash[:12]>/   one render per (sequence, speed) (simspad.io.render_dir)
    <out>/recordings/<sequence>/<sequence>[_x<k>]_<lux>lx.h5  one recording per (sequence, speed, lux)

``_x<k>`` appears for a speed factor k ≠ 1 only (simspad.dataset.speed).

A lock (``fcntl.flock`` on ``<out>/.simspad.lock``) refuses a second concurrent run on one output directory; the
kernel releases it when the process dies, even by kill -9, and the next run removes the temporary files the
dead one left (the lock guarantees no one else is writing them).
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

from simspad.errors import SimSpadError
from simspad.io.names import lux_label, speed_suffix
from simspad.io.output_dirs import LOCK_NAME, OutputLock
from simspad.io.render_dir import read_render_dir
from simspad.render.keyframe_files import frame_is_intact

RENDERS_DIR = "renders"
RECORDINGS_DIR = "recordings"
#: Temporary names written by simspad.io.atomic.temporary_sibling: ``.<name>.tmp-<pid>-<8 hex>``.
_TMP_NAME = re.compile(r"^\..+\.tmp-\d+-[0-9a-f]{8}$")


def recording_rel_path(sequence_name: str, lux: float, speed: float = 1.0) -> str:
    """``recordings/<sequence>/<sequence>_<lux>lx.h5`` (speed 1), ``.../<sequence>_x<speed>_<lux>lx.h5`` (others)."""
    return f"{RECORDINGS_DIR}/{sequence_name}/{sequence_name}{speed_suffix(speed)}_{lux_label(lux)}lx.h5"



class DatasetLock(OutputLock):
    """The lock of a dataset folder (:class:`simspad.io.output_dirs.OutputLock`, the one ``evaluate`` and the
    other commands take on their output folders): a second run on the same directory is refused at once with a
    clear message. The kernel releases the lock when the process dies, even by kill -9."""

    def __init__(self, out_dir: Path):
        super().__init__(out_dir, "simspad generate", what="dataset")


def remove_temporaries(out_dir: Path) -> list[Path]:
    """Delete the temporary files and folders a killed run left behind (``.<name>.tmp-<pid>-<hex>``)."""
    removed = []
    roots = [out_dir, out_dir / RENDERS_DIR, out_dir / RECORDINGS_DIR]
    rec_root = out_dir / RECORDINGS_DIR
    if rec_root.is_dir() and not rec_root.is_symlink():  # never delete through a link that leads out of the dataset
        roots += [p for p in rec_root.iterdir() if p.is_dir() and not p.is_symlink()]
    ren_root = out_dir / RENDERS_DIR
    # keyframes and timeline.json are written in place (each atomically): a killed render leaves its temporary
    # names there
    if ren_root.is_dir() and not ren_root.is_symlink():
        for p in ren_root.iterdir():
            if p.is_dir() and not p.is_symlink() and not _TMP_NAME.match(p.name):
                roots += [p, p / "frames"]
    for root in roots:
        if not root.is_dir() or root.is_symlink():
            continue
        for p in root.iterdir():
            if _TMP_NAME.match(p.name):
                if p.is_dir() and not p.is_symlink():
                    shutil.rmtree(p, ignore_errors=True)
                else:
                    p.unlink(missing_ok=True)
                removed.append(p)
    return removed


#: What a dataset folder may hold before its first manifest (a run killed early, renders copied in by hand).
_DATASET_ENTRIES = {LOCK_NAME, RENDERS_DIR, RECORDINGS_DIR, "manifest.json"}


def check_dataset_owner(out_dir: Path, previous: dict | None, spec_name: str) -> None:
    """Refuse to write the dataset ``spec_name`` into a folder that belongs to another dataset or holds other files.

    A dataset folder belongs to the spec ``name`` recorded in its manifest: a mistyped ``--out`` naming another
    dataset must not overwrite (or prune) that dataset's recordings. A folder without a manifest may hold only
    what a run writes (``renders/``, ``recordings/``, the lock, temporaries), so ``--out ~`` is refused too.
    """
    if previous is not None:
        owner = previous.get("name")
        if owner != spec_name:
            raise SimSpadError(f"this folder holds the dataset {owner!r}, not {spec_name!r}; refusing to overwrite it "
                               "(choose another --out, or set name in the spec to match)", path=out_dir,
                               field="--out")
        return
    foreign = sorted(p.name for p in out_dir.iterdir() if p.name not in _DATASET_ENTRIES
                     and not _TMP_NAME.match(p.name))
    if foreign:
        shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise SimSpadError(f"not empty and not a SimSPAD dataset (holds {shown}); choose an empty or new folder "
                           "for --out", path=out_dir, field="--out")


def check_prune(out_dir: Path, obsolete: list[str], prune: bool, log) -> None:
    """Recordings and renders of the previous manifest that the spec no longer lists are deleted only when
    ``prune`` is given; otherwise refuse, naming them, so a changed spec never silently deletes data."""
    present = [rel for rel in obsolete if (out_dir / rel).exists()]
    if not present:
        return
    for rel in present:
        check_inside_dataset(out_dir, rel)
    shown = ", ".join(present[:6]) + (f" and {len(present) - 6} more" if len(present) > 6 else "")
    if not prune:
        raise SimSpadError(f"the spec no longer lists {len(present)} item(s) of this dataset: {shown}; re-run with "
                           "--prune to delete them, or choose another --out", path=out_dir, field="--out")
    log(f"--prune: removing {len(present)} item(s) no longer in the spec: {shown}")


def check_no_links_out(out_dir: Path) -> None:
    """Refuse a dataset folder whose ``recordings/``, ``renders/`` or their sub-folders are symbolic links leading
    out of it: a run deletes there (``--prune``, a damaged render's ``timeline.json``, stale keyframes, a killed
    run's temporaries), and must not delete outside the dataset; ``evaluate`` refuses such recordings too."""
    inside = out_dir.resolve()
    candidates = [out_dir / RECORDINGS_DIR, out_dir / RENDERS_DIR]
    for root in candidates[:2]:
        if root.is_dir() and not root.is_symlink():
            candidates += sorted(root.iterdir())
    candidates += [p / "frames" for p in candidates if p.parent.name == RENDERS_DIR and p.is_dir()]
    for p in candidates:
        if not p.is_symlink():
            continue
        try:
            target = p.resolve()
        except (OSError, RuntimeError):  # a link loop
            target = None
        if target is None or not target.is_relative_to(inside):
            raise SimSpadError(f"{p.relative_to(out_dir)} is a symbolic link to {target or 'a loop'}, outside the "
                               "dataset; a run deletes files there (--prune, damaged renders, temporaries) and "
                               "SimSPAD deletes only inside the dataset folder: replace the link by the folder "
                               "itself", path=out_dir, field="--out")


def check_inside_dataset(out_dir: Path, rel: str) -> Path:
    """``out_dir / rel`` if no part of it below ``out_dir`` is a symbolic link and ``rel`` has no ``..``: a file
    deleted there is the dataset's own. Otherwise a :class:`SimSpadError` naming the link (nothing is deleted)."""
    parts = Path(rel).parts
    if not rel or Path(rel).is_absolute() or ".." in parts:
        raise SimSpadError(f"the manifest names {rel!r}, which leaves the dataset folder; refusing to delete it",
                           path=out_dir / "manifest.json", field="path")
    here = out_dir
    for part in parts:
        here = here / part
        if here.is_symlink():
            raise SimSpadError(f"{here.relative_to(out_dir)} is a symbolic link; refusing to delete through it "
                               f"(it would delete {rel} outside the dataset): replace the link by a folder or "
                               "choose another --out", path=out_dir, field="--prune")
    return out_dir / rel


def check_render_cache(render_dir: Path, log) -> bool:
    """Verify a finished render of the dataset (``timeline.json`` and every keyframe decodes completely); if any
    part is damaged (a truncated EXR, a corrupt timeline), log which and remove ``timeline.json`` so the render
    runs again instead of every later simulation failing on it. Returns True when the render is intact."""
    meta = render_dir / "timeline.json"
    if not meta.is_file():
        return False
    try:
        index = read_render_dir(render_dir)
        bad = [f for f in index.files if not frame_is_intact(f)]
        problem = f"damaged keyframe {bad[0].name} ({len(bad)} of {len(index.files)})" if bad else None
    except SimSpadError as exc:
        problem = exc.message
    if problem is None:
        return True
    log(f"render {render_dir.name}: {problem}; rendering it again")
    meta.unlink(missing_ok=True)
    return False
