"""Outputs: nothing is deleted that the command did not write (docs/trust.md, issue 33 goal 1).

Every ``--out`` is new, empty, or a folder the same command wrote before (its marker ``.simspad-<command>``); a
re-run replaces only that command's files; anything else is refused in one line, exit 2, before any work. Each
case puts a user's file where the command used to delete it and checks that it survives, byte for byte. Real
``simspad`` processes throughout (the ``simspad_cli`` fixture); the shared evaluation dataset is copied before a
test writes near it.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from simspad.errors import SimSpadError
from simspad.io.atomic import atomic_path
from simspad.io.hashing import file_sha256
from simspad.io.output_dirs import OutputLock, marker_name
from simspad.io.render_dir import write_render_dir
from tests.helpers.evaluation_data import write_recording, write_submission
from tests.helpers.synthetic_recordings import write_recording as synthetic_recording

PRECIOUS = b"a user's own notes\n"


def _tree(root: Path) -> dict[str, str]:
    """Every file below ``root`` (relative path -> sha256), links not followed; the lock file's holder line,
    rewritten by every run that takes the lock, is left out."""
    return {p.relative_to(root).as_posix(): file_sha256(p) for p in sorted(root.rglob("*"))
            if p.is_file() and not p.is_symlink() and p.name != ".simspad.lock"}


def _one_line_refusal(proc: subprocess.CompletedProcess, *fragments: str) -> str:
    lines = [ln for ln in proc.stderr.replace("\r", "\n").splitlines() if ln.strip()]
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert len(lines) == 1 and lines[0].startswith("simspad: error: "), proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr
    for f in fragments:
        assert f in lines[0], lines[0]
    return lines[0]


@pytest.fixture
def dataset_copy(evaluation_dataset, tmp_path) -> Path:
    """A private copy of the session's evaluation dataset (two SPAD recordings and a manifest)."""
    return Path(shutil.copytree(evaluation_dataset, tmp_path / "dataset"))


def _precious(folder: Path, name: str = "precious.txt") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_bytes(PRECIOUS)
    return folder / name


# ------------------------------------------------------------------------------------------------ atomic_path
def test_atomic_path_never_deletes_a_folder_to_put_another_there(tmp_path):
    """The root of the old data loss: a folder written through atomic_path replaced a non-empty folder whole
    (shutil.rmtree). Now it replaces only a missing or empty folder, and its temporary is gone either way."""
    target = tmp_path / "out"
    user_file = _precious(target)
    with pytest.raises(SimSpadError, match="not empty; refusing to replace it"):
        with atomic_path(target) as tmp:
            tmp.mkdir()
            (tmp / "new.txt").write_text("new")
    assert user_file.read_bytes() == PRECIOUS and sorted(p.name for p in target.iterdir()) == ["precious.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no temporary left behind

    empty = tmp_path / "empty"
    empty.mkdir()
    with atomic_path(empty) as tmp:
        tmp.mkdir()
        (tmp / "new.txt").write_text("new")
    assert (empty / "new.txt").read_text() == "new"


# ----------------------------------------------------------------------------------------------------- export
def test_export_npz_refuses_a_folder_it_did_not_write(dataset_copy, tmp_path, simspad_cli):
    rec = dataset_copy / "recordings/ramp/ramp_10lx.h5"
    foreign = tmp_path / "folder"
    _precious(foreign)
    before = _tree(foreign)
    proc = simspad_cli.run("export", rec, "--to", "npz", "--out", foreign)
    _one_line_refusal(proc, str(foreign), "--out", "not empty", "precious.txt")
    assert _tree(foreign) == before and sorted(os.listdir(foreign)) == ["precious.txt"]


def test_export_npz_into_the_recordings_folder_keeps_the_recording(dataset_copy, simspad_cli):
    """``--out dataset/recordings/ramp`` used to delete the recording being exported (and its sibling)."""
    rec = dataset_copy / "recordings/ramp/ramp_10lx.h5"
    before = _tree(dataset_copy)
    proc = simspad_cli.run("export", rec, "--to", "npz", "--out", rec.parent)
    _one_line_refusal(proc, "not empty", "ramp_100lx.h5")
    proc = simspad_cli.run("export", rec, "--to", "npz", "--out", dataset_copy)
    _one_line_refusal(proc, "not empty", "manifest.json")
    assert _tree(dataset_copy) == before


def test_export_npz_again_replaces_only_its_own_files(tmp_path, simspad_cli):
    """A re-run into its own folder keeps a user's file, and deletes the file its previous run wrote that this
    run does not write (spad.npz, when the second recording has no SPAD)."""
    with_spad = write_recording(tmp_path / "a.h5")
    without_spad = write_recording(tmp_path / "b.h5", with_spad=False)
    out = tmp_path / "export"
    assert simspad_cli.run("export", with_spad, "--to", "npz", "--out", out).returncode == 0
    marker = json.loads((out / marker_name("export-npz")).read_text())
    assert marker["command"] == "export-npz" and "spad.npz" in marker["files"]
    notes = _precious(out, "notes.txt")
    _precious(out / "gt", "my_annotation.txt")  # inside a folder the export writes into
    proc = simspad_cli.run("export", without_spad, "--to", "npz", "--out", out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert notes.read_bytes() == PRECIOUS and (out / "gt/my_annotation.txt").read_bytes() == PRECIOUS
    assert not (out / "spad.npz").exists()  # its own file of the previous run, no longer written
    assert json.loads((out / "metadata.json").read_text())["recording"] == str(without_spad)
    assert "spad.npz" not in json.loads((out / marker_name("export-npz")).read_text())["files"]


@pytest.mark.parametrize("fmt", ["dsec", "evt3"])
def test_file_export_replaces_only_an_earlier_export_of_its_format(fmt, dataset_copy, tmp_path, simspad_cli):
    """A file --out is replaced only when it is the command's own kind: ``export --to dsec --out OTHER.h5`` used
    to replace another recording (or any file) whole."""
    rec = tmp_path / "events.h5"
    synthetic_recording(rec, lambda t: np.full((12, 16), 1e15) * (1.5 + np.sin(300 * t)), spad=False, frames=False)
    victim = dataset_copy / "recordings/ramp/ramp_100lx.h5"
    digest = file_sha256(victim)
    _one_line_refusal(simspad_cli.run("export", rec, "--to", fmt, "--out", victim), "is not a file of",
                      f"export --to {fmt}")
    assert file_sha256(victim) == digest
    notes = _precious(tmp_path, "notes.raw")
    _one_line_refusal(simspad_cli.run("export", rec, "--to", fmt, "--out", notes), "refusing to replace it")
    assert notes.read_bytes() == PRECIOUS
    out = tmp_path / f"out.{fmt}"
    for _ in range(2):  # the second run replaces the first's file: its own kind
        proc = simspad_cli.run("export", rec, "--to", fmt, "--out", out)
        assert proc.returncode == 0, proc.stderr[-3000:]


def test_simulate_and_snr_replace_only_their_own_kind_of_file(tmp_path, simspad_cli):
    render = write_render_dir(tmp_path / "render", [0.0, 0.002], np.full((2, 6, 8, 3), 0.5, np.float32)).parent
    thesis = _precious(tmp_path, "thesis.h5")
    args = ("simulate", render, "--lux", 100, "--sensors", "spad")
    _one_line_refusal(simspad_cli.run(*args, "--out", thesis), "is not a SimSPAD recording")
    _one_line_refusal(simspad_cli.run("snr", "--out", thesis), "is not a PNG image")
    assert thesis.read_bytes() == PRECIOUS
    rec = tmp_path / "rec.h5"
    for _ in range(2):  # a recording simulate wrote is replaced by the next run
        proc = simspad_cli.run(*args, "--out", rec)
        assert proc.returncode == 0, proc.stderr[-3000:]


# --------------------------------------------------------------------------------------------------- evaluate
def test_evaluate_again_keeps_notes_and_the_leaderboard(dataset_copy, tmp_path, simspad_cli):
    """``evaluate --out RESULTS`` run again used to delete everything else in RESULTS: a user's notes and the
    leaderboard that ``simspad leaderboard RESULTS`` wrote there by default."""
    results = tmp_path / "results"
    assert simspad_cli.run("evaluate", dataset_copy, "--methods", "ni", "--out", results).returncode == 0
    proc = simspad_cli.run("leaderboard", results)
    assert proc.returncode == 0, proc.stderr[-3000:]
    board = {n: file_sha256(results / n) for n in ("leaderboard.html", "leaderboard.md", "leaderboard.csv")}
    notes = _precious(results, "notes.txt")
    own_image = results / "images/ramp_100lx/ni.png"
    assert own_image.is_file()
    # Again, on one recording only: the other recording's images (its own files) go, nothing else does.
    proc = simspad_cli.run("evaluate", dataset_copy / "recordings/ramp/ramp_10lx.h5", "--methods", "ni",
                           "--out", results)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert notes.read_bytes() == PRECIOUS
    assert {n: file_sha256(results / n) for n in board} == board
    assert not own_image.exists() and not (results / "images/ramp_100lx").exists()
    assert (results / "images/ramp_10lx/ni.png").is_file()
    assert [r["recording"] for r in json.loads((results / "results.json").read_text())["results"]] == \
        ["ramp_10lx.h5"]
    # the leaderboard can be rebuilt in place: evaluate's folder is one it may write into
    assert simspad_cli.run("leaderboard", results).returncode == 0 and notes.read_bytes() == PRECIOUS


def test_evaluate_refuses_a_folder_it_did_not_write(dataset_copy, tmp_path, simspad_cli):
    foreign = tmp_path / "mine"
    _precious(foreign)
    (foreign / "results.json").write_text('{"format": "something else"}')  # not SimSPAD's, whatever its name
    before = _tree(foreign)
    proc = simspad_cli.run("evaluate", dataset_copy, "--methods", "ni", "--out", foreign)
    _one_line_refusal(proc, str(foreign), "not empty", "simspad evaluate")
    assert _tree(foreign) == before and sorted(os.listdir(foreign)) == ["precious.txt", "results.json"]
    # nor into the dataset itself
    before = _tree(dataset_copy)
    _one_line_refusal(simspad_cli.run("evaluate", dataset_copy, "--methods", "ni", "--out", dataset_copy),
                      "manifest.json")
    assert _tree(dataset_copy) == before


def test_two_concurrent_evaluations_of_one_folder_second_is_refused(dataset_copy, tmp_path, simspad_cli):
    """Both used to exit 0, the last writer silently winning. The first is held still (SIGSTOP) while it owns
    the folder's lock, so the second certainly runs while it is writing."""
    results = tmp_path / "results"
    first = subprocess.Popen(simspad_cli.command("evaluate", dataset_copy, "--methods", "ni", "--out", results),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=simspad_cli.env)
    try:
        lock = results / ".simspad.lock"
        deadline = time.monotonic() + 120
        while first.poll() is None and time.monotonic() < deadline:
            if lock.is_file() and lock.read_text().strip():  # written once the lock is held
                break
            time.sleep(0.02)
        assert first.poll() is None, "the first evaluation ended before the second could start"
        os.kill(first.pid, signal.SIGSTOP)
        try:
            second = simspad_cli.run("evaluate", dataset_copy, "--methods", "ni", "--out", results)
        finally:
            os.kill(first.pid, signal.SIGCONT)
        _one_line_refusal(second, "already writing this folder", "simspad evaluate")
        out, err = first.communicate(timeout=300)
    finally:
        if first.poll() is None:
            first.kill()
            first.communicate()
    assert first.returncode == 0, err[-3000:]
    assert (results / "results.csv").is_file()


def test_evaluate_takes_the_lock_generate_takes(dataset_copy, simspad_cli):
    """The lock is the one ``generate`` takes: a dataset folder being generated is refused as --out (it is
    not empty and not evaluate's); a results folder locked by any SimSPAD command is refused too."""
    results = dataset_copy.parent / "results"
    results.mkdir()
    with OutputLock(results, "simspad generate"):
        proc = simspad_cli.run("evaluate", dataset_copy, "--methods", "ni", "--out", results)
    _one_line_refusal(proc, "already writing", "simspad generate")
    assert sorted(os.listdir(results)) == [".simspad.lock"]


# ------------------------------------------------------------------------------------------ score, leaderboard
def test_score_refuses_a_folder_it_did_not_write_and_keeps_user_files(dataset_copy, tmp_path, simspad_cli):
    submission = write_submission(tmp_path / "sub.h5", dataset_copy)
    foreign = tmp_path / "foreign"
    _precious(foreign)
    _one_line_refusal(simspad_cli.run("score", submission, "--dataset", dataset_copy, "--out", foreign),
                      "not empty", "simspad score")
    assert sorted(os.listdir(foreign)) == ["precious.txt"]
    out = tmp_path / "scored"
    assert simspad_cli.run("score", submission, "--dataset", dataset_copy, "--out", out).returncode == 0
    notes = _precious(out, "notes.txt")
    proc = simspad_cli.run("score", submission, "--dataset", dataset_copy, "--out", out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert notes.read_bytes() == PRECIOUS and (out / "results.csv").is_file()
    # evaluate does not take over score's folder, nor the other way round
    _one_line_refusal(simspad_cli.run("evaluate", dataset_copy, "--methods", "ni", "--out", out), "simspad evaluate")


def test_leaderboard_refuses_a_folder_that_is_not_results_or_a_leaderboard(evaluation_dataset, tmp_path,
                                                                          simspad_cli):
    results = tmp_path / "results"
    assert simspad_cli.run("evaluate", evaluation_dataset, "--methods", "ni", "--out", results).returncode == 0
    foreign = tmp_path / "home"
    _precious(foreign, "leaderboard.md")  # a user's file of the very name the leaderboard writes
    proc = simspad_cli.run("leaderboard", results, "--out", foreign)
    _one_line_refusal(proc, "not empty", "simspad leaderboard")
    assert sorted(os.listdir(foreign)) == ["leaderboard.md"] and (foreign / "leaderboard.md").read_bytes() == PRECIOUS
    new = tmp_path / "board"
    assert simspad_cli.run("leaderboard", results, "--out", new).returncode == 0
    notes = _precious(new, "notes.txt")
    assert simspad_cli.run("leaderboard", results, "--out", new).returncode == 0
    assert notes.read_bytes() == PRECIOUS


# ----------------------------------------------------------------------------------------------------- render
def test_render_refuses_a_dataset_folder(dataset_copy, simspad_cli):
    """``render --out`` into a non-empty dataset folder used to mix keyframes into it."""
    before = _tree(dataset_copy)
    proc = simspad_cli.run("render", "siemens-star", "--duration", "0.002", "--resolution", "16x12", "--spp", "4",
                           "--out", dataset_copy)
    _one_line_refusal(proc, "not empty", "manifest.json", "simspad render")
    assert _tree(dataset_copy) == before and not (dataset_copy / "frames").exists()
    assert not (dataset_copy / ".simspad.lock").exists()


@pytest.mark.slow
def test_render_again_in_its_folder_keeps_user_files(tmp_path, simspad_cli):
    out = tmp_path / "render"
    args = ("render", "siemens-star", "--duration", "0.002", "--resolution", "16x12", "--spp", "4", "--out", out)
    assert simspad_cli.run(*args).returncode == 0
    marker = json.loads((out / marker_name("render")).read_text())
    assert "timeline.json" in marker["files"] and any(f.startswith("frames/") for f in marker["files"])
    notes = _precious(out, "notes.txt")
    proc = simspad_cli.run(*args)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert notes.read_bytes() == PRECIOUS and "re-used" in proc.stdout


# --------------------------------------------------------------------------------------------- generate --prune
_PRUNE_SPEC = """
name = "prune"
seed = 1
lux = [100]
{sequences}
[sensors.spad]
preset = "swissspad2"
"""
_SEQUENCE = """
[[sequences]]
name = "{name}"
scene = "siemens-star"
duration_s = 0.002
resolution = [16, 12]
spp = 2
"""


@pytest.mark.slow
def test_prune_never_deletes_through_a_symbolic_link(tmp_path, simspad_cli):
    """``generate --prune`` used to delete files outside the dataset when ``recordings/<seq>`` is a symbolic
    link; now it refuses the layout (as ``evaluate`` does), naming the link, and deletes nothing."""
    both = tmp_path / "both.toml"
    both.write_text(_PRUNE_SPEC.format(sequences=_SEQUENCE.format(name="a") + _SEQUENCE.format(name="b")))
    only_a = tmp_path / "only_a.toml"
    only_a.write_text(_PRUNE_SPEC.format(sequences=_SEQUENCE.format(name="a")))
    out = tmp_path / "dataset"
    proc = simspad_cli.run("generate", both, "--out", out, "--workers", 1)
    assert proc.returncode == 0, proc.stderr[-3000:]
    outside = tmp_path / "elsewhere"
    shutil.move(out / "recordings/b", outside)  # the user keeps sequence b on another disk, linked in
    (out / "recordings/b").symlink_to(outside, target_is_directory=True)
    _precious(outside, "precious.txt")
    kept_outside, kept_inside = _tree(outside), _tree(out)
    proc = simspad_cli.run("generate", only_a, "--out", out, "--workers", 1, "--prune")
    _one_line_refusal(proc, "recordings/b is a symbolic link", "outside the dataset")
    assert _tree(outside) == kept_outside and (outside / "b_100lx.h5").is_file()
    assert _tree(out) == kept_inside
    # the same without --prune: a run also deletes damaged renders and temporaries, so the layout is refused
    _one_line_refusal(simspad_cli.run("generate", both, "--out", out, "--workers", 1), "recordings/b is a symbolic")
    assert _tree(outside) == kept_outside and _tree(out) == kept_inside
