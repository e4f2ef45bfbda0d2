"""Disk full is one clear line in every command (docs/trust.md, "Runs: bounded, or refused up front").

Each command writes onto a real small filesystem (a tmpfs of a few KiB to a few hundred KiB, mounted for the
test; skipped where this process may not mount) until the disk is full. Before: ``evaluate`` ended in two h5py
tracebacks and ``internal error: BrokenProcessPool``, ``export --to dsec`` printed the right line and then crashed
(SIGSEGV), ``export --to aedat4`` aborted the process (SIGABRT) from dv-processing's writer thread and left its
temporary file. Now: exit status 2, the last line of stderr names the output and the full disk, no traceback, and
no file left on the full disk.
"""

from __future__ import annotations

import subprocess
import uuid
from pathlib import Path

import numpy as np
import pytest

from simspad.io.render_dir import write_render_dir
from simspad.sensors.presets import sensor_params
from simspad.sensors.simulate import RecordingSettings, simulate_recording
from tests.helpers.evaluation_data import write_submission


def _mount_tmpfs(where: Path, size: str) -> None:
    where.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size},mode=0755", f"simspad-{uuid.uuid4().hex[:8]}",
                           str(where)], capture_output=True, text=True)
    if proc.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here ({proc.stderr.strip() or 'not permitted'}): run as root")


@pytest.fixture()
def small_disk(tmp_path):
    """``small_disk(size)``: a folder on a fresh tmpfs of ``size`` (``"16k"``), unmounted after the test."""
    mounted = []

    def make(size: str) -> Path:
        where = tmp_path / f"disk{len(mounted)}"
        _mount_tmpfs(where, size)
        mounted.append(where)
        return where

    yield make
    for where in mounted:
        subprocess.run(["umount", "-l", str(where)], capture_output=True)


def _left(disk: Path) -> list[str]:
    return sorted(str(p.relative_to(disk)) for p in disk.rglob("*") if p.is_file())


def _assert_one_disk_full_line(proc, disk: Path, *, phrase: str = "the disk is full") -> None:
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-3000:])  # not 1 (internal), 134 or 139 (crash)
    lines = [line for line in proc.stderr.replace("\r", "\n").splitlines() if line.strip()]
    last = lines[-1]
    assert last.startswith("simspad: error: ") and str(disk) in last and phrase in last, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr and "internal error" not in proc.stderr, proc.stderr[-3000:]
    assert sum(line.startswith("simspad:") for line in lines) == 1


@pytest.fixture(scope="module")
def event_recording(tmp_path_factory) -> Path:
    """A 32 × 24 px, 50 ms recording with SPAD, frames and ~10⁴ events (its DSEC export takes ~40 KiB)."""
    root = tmp_path_factory.mktemp("events")
    times = np.linspace(0.0, 0.05, 51)
    base = np.random.default_rng(0).uniform(0.2, 1.0, (24, 32, 3))
    frames = [(base * (1.0 + 0.4 * np.sin(900 * t))).astype(np.float32) for t in times]
    render = write_render_dir(root / "render", times, frames).parent
    sensors = {kind: sensor_params(kind) for kind in ("spad", "frames", "events")}
    return simulate_recording(render, root / "rec.h5", RecordingSettings(lux=100.0, sensors=sensors, seed=1))


EXPORTS = [("dsec", "events.h5", "4k"), ("dsec", "events.h5", "24k"), ("evt3", "events.raw", "8k"),
           ("evt3", "events.raw", "32k"), ("npz", "npz", "8k"), ("npz", "npz", "300k"),
           ("aedat4", "events.aedat4", "8k"), ("aedat4", "events.aedat4", "300k")]


@pytest.mark.parametrize("fmt, name, size", EXPORTS)
def test_every_exporter_reports_a_full_disk_in_one_line(simspad_cli, small_disk, event_recording, fmt, name, size):
    if fmt == "aedat4":
        pytest.importorskip("dv_processing")
    disk = small_disk(size)
    proc = simspad_cli.run("export", event_recording, "--to", fmt, "--out", disk / name)
    _assert_one_disk_full_line(proc, disk, phrase="the disk is too full" if fmt == "aedat4" else "the disk is full")
    assert _left(disk) == []


@pytest.mark.parametrize("size", ["16k", "40k", "100k", "200k"])  # before any file, and mid-way through the runs
def test_evaluate_reports_a_full_disk_in_one_line(simspad_cli, small_disk, evaluation_dataset, size):
    disk = small_disk(size)
    proc = simspad_cli.run("evaluate", evaluation_dataset, "--methods", "ni,qbp", "--out", disk / "res")
    _assert_one_disk_full_line(proc, disk)
    assert _left(disk) == []


def test_simulate_reports_a_full_disk_in_one_line(simspad_cli, small_disk, event_recording):
    render = event_recording.parent / "render"
    disk = small_disk("300k")
    # the size check refuses this recording up front; lifted, the disk fills while the recording is written
    proc = simspad_cli.run("simulate", render, "--lux", "10", "--sensors", "spad,frames,events", "--out",
                           disk / "rec.h5", env={"SIMSPAD_IGNORE_LIMITS": "1"})
    _assert_one_disk_full_line(proc, disk)
    assert _left(disk) == []


@pytest.mark.parametrize("size", ["8k", "20k"])
def test_score_reports_a_full_disk_in_one_line(simspad_cli, small_disk, evaluation_dataset, tmp_path, size):
    sub = write_submission(tmp_path / "sub.h5", evaluation_dataset)
    disk = small_disk(size)
    proc = simspad_cli.run("score", sub, "--dataset", evaluation_dataset, "--out", disk / "res")
    _assert_one_disk_full_line(proc, disk)
    assert _left(disk) == []


@pytest.mark.parametrize("size", ["8k", "100k"])
def test_leaderboard_and_snr_report_a_full_disk_in_one_line(simspad_cli, small_disk, evaluation_dataset, tmp_path,
                                                            size):
    sub = write_submission(tmp_path / "sub.h5", evaluation_dataset)
    assert simspad_cli.run("score", sub, "--dataset", evaluation_dataset, "--out", tmp_path / "res").returncode == 0
    disk = small_disk(size)
    # each leaderboard file is written atomically: the ones finished before the disk filled stay, whole
    _assert_one_disk_full_line(simspad_cli.run("leaderboard", tmp_path / "res", "--out", disk / "board"), disk)
    assert not any(".tmp" in p for p in _left(disk))
    disk = small_disk("8k")
    _assert_one_disk_full_line(simspad_cli.run("snr", "--out", disk / "snr.png"), disk)
    assert _left(disk) == []


TINY_SPEC = """
name = "tiny"
seed = 1
output = "out"
lux = [10]
[[sequences]]
scene = "office"
duration_s = 0.004
resolution = [32, 24]
spp = 4
[sensors.spad]
preset = "swissspad2"
"""


@pytest.mark.slow
@pytest.mark.parametrize("size", ["16k", "150k"])  # the render fills it / the recording does
def test_render_and_generate_report_a_full_disk_in_one_line(simspad_cli, small_disk, tmp_path, size):
    spec = tmp_path / "tiny.toml"
    spec.write_text(TINY_SPEC)
    disk = small_disk(size)
    proc = simspad_cli.run("generate", spec, "--out", disk / "data", "--yes")
    _assert_one_disk_full_line(proc, disk)
    assert not any(p.endswith((".h5", ".exr")) and "/." in f"/{p}" for p in _left(disk))  # no temporary left
    disk = small_disk("8k")
    proc = simspad_cli.run("render", "office", "--duration", "0.004", "--resolution", "32x24", "--spp", "4",
                           "--out", disk / "render")
    _assert_one_disk_full_line(proc, disk)
    assert _left(disk) == []
