"""Smaller promises about outputs (docs/trust.md, "Smaller promises"; issue 33 goal 4): a spec's ``output`` stays
below the current directory unless it is absolute, recordings are byte-identical wherever the spec sits,
``simspad info`` fails on a recording that no longer matches its sha256, and SIGTERM leaves no temporary file.
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

from simspad.bundled import DATASETS_DIR
from simspad.dataset.plan import make_plan
from simspad.dataset.spec_validation import load_spec
from simspad.io.hashing import file_sha256
from simspad.io.render_dir import write_render_dir


def _stderr_lines(proc) -> list[str]:
    return [ln for ln in proc.stderr.replace("\r", "\n").splitlines() if ln.strip()]


# ---------------------------------------------------------------------------------------------- spec `output`
def test_spec_output_may_not_walk_out_of_the_current_directory(tmp_path, simspad_cli):
    """``output = "../../../../tmp/escaped"`` used to be written there; a relative output now stays below the
    current directory (an absolute one is an explicit choice, and --out overrides either)."""
    cwd = tmp_path / "a/b/c/d"
    cwd.mkdir(parents=True)
    spec = cwd / "spec.toml"
    spec.write_text('name = "esc"\noutput = "../../../../escaped"\nlux = [10]\n[[sequences]]\n'
                    'scene = "siemens-star"\nduration_s = 0.002\nresolution = [16, 12]\nspp = 2\n')
    for args in (("generate", spec), ("info", spec)):
        proc = subprocess.run(simspad_cli.command(*args), cwd=cwd, env=simspad_cli.env, capture_output=True,
                              text=True, timeout=300)
        lines = _stderr_lines(proc)
        assert proc.returncode == 2, proc.stderr[-3000:]
        assert len(lines) == 1 and "output" in lines[0] and "leaves the current directory" in lines[0], lines
        assert "Traceback" not in proc.stderr
    assert not (tmp_path / "escaped").exists()
    assert sorted(p.name for p in cwd.iterdir()) == ["spec.toml"]


# --------------------------------------------------------------------------- recordings wherever the spec sits
def _recording_metadata(spec_path: Path) -> list[dict]:
    plan = make_plan(load_spec(spec_path), "2025-01-01T00:00:00Z")
    return [dict(r.metadata) for r in plan.recordings]


def test_bundled_trajectories_are_stored_the_same_wherever_the_spec_sits(tmp_path):
    """The bundled trajectory used to be stored as a path relative to the spec's folder
    (``../../../…/trajectories/…`` for a copied spec): now it is stored relative to the bundled
    specs' folder, as the bundled spec itself has always stored it (so those recordings keep their bytes)."""
    bundled = _recording_metadata(DATASETS_DIR / "mini.toml")
    for where in ("here", "much/deeper/down"):
        folder = tmp_path / where
        folder.mkdir(parents=True)
        shutil.copy(DATASETS_DIR / "mini.toml", folder / "mini.toml")
        assert _recording_metadata(folder / "mini.toml") == bundled
    trajectories = {m["trajectory"] for m in bundled}
    assert trajectories == {"../trajectories/office_handheld_pan.toml", "../trajectories/piano_fast_orbit.toml",
                            "../trajectories/plant_handheld_pan.toml", "../trajectories/siemens-star.toml",
                            "../trajectories/fan.toml"}
    assert all(str(tmp_path) not in json.dumps(m) for m in bundled)


_SPEC = """
name = "where"
seed = 3
lux = [100]
[[sequences]]
name = "star"
scene = "siemens-star"
trajectory = "siemens-star.toml"
duration_s = 0.002
resolution = [16, 12]
spp = 2
[sensors.spad]
preset = "swissspad2"
"""


@pytest.mark.slow
def test_recordings_are_byte_identical_wherever_the_spec_sits(tmp_path, simspad_cli):
    """The same spec (naming a bundled trajectory) in two folders at different depths gives the same bytes."""
    digests = []
    for where in ("a", "deeper/and/deeper/b"):
        folder = tmp_path / where
        folder.mkdir(parents=True)
        (folder / "spec.toml").write_text(_SPEC)
        out = tmp_path / f"out-{len(digests)}"
        proc = simspad_cli.run("generate", folder / "spec.toml", "--out", out, "--workers", 1,
                               env={"SOURCE_DATE_EPOCH": "1735689600"})
        assert proc.returncode == 0, proc.stderr[-3000:]
        digests.append(file_sha256(out / "recordings/star/star_100lx.h5"))
    assert digests[0] == digests[1]


# ---------------------------------------------------------------------------------------------- info's exit
def test_info_exits_1_when_a_recording_fails_its_hash(evaluation_dataset, tmp_path, simspad_cli):
    """``simspad info`` printed CORRUPT for a bad hash yet exited 0: scripts and CI could not see it."""
    intact = simspad_cli.run("info", evaluation_dataset)
    assert intact.returncode == 0 and "CORRUPT" not in intact.stdout, intact.stderr[-3000:]
    dataset = Path(shutil.copytree(evaluation_dataset, tmp_path / "dataset"))
    rec = dataset / "recordings/ramp/ramp_100lx.h5"
    data = bytearray(rec.read_bytes())
    data[len(data) // 2] ^= 0xFF  # one flipped byte: same size, different sha256
    rec.write_bytes(bytes(data))
    proc = simspad_cli.run("info", dataset)
    assert proc.returncode == 1, proc.stderr[-3000:]
    assert "CORRUPT     recordings/ramp/ramp_100lx.h5" in proc.stdout  # the summary is still printed
    lines = _stderr_lines(proc)
    assert len(lines) == 1 and "1 recording(s) do not match the sha256" in lines[0], lines
    assert "Traceback" not in proc.stderr


# ------------------------------------------------------------------------------------------------ SIGTERM
def test_sigterm_on_simulate_leaves_no_temporary_file(tmp_path, simspad_cli):
    """SIGTERM (``kill PID``, a batch system's time limit) used to leave a 110 MB ``.<name>.tmp-…`` until a later
    write of the same name; it now runs the same clean-up as Ctrl-C and exits 143 after one line."""
    render = tmp_path / "render"
    write_render_dir(render, [0.0, 0.2], np.full((2, 96, 128, 3), 0.5, np.float32),
                     depth=np.ones((2, 96, 128), np.float32), scene="flat", trajectory="none")
    out = tmp_path / "out" / "rec.h5"
    proc = subprocess.Popen(simspad_cli.command("simulate", render, "--lux", 100, "--sensors", "spad", "--out", out),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=simspad_cli.env)
    try:
        deadline = time.monotonic() + 120
        temporaries: list[Path] = []
        while proc.poll() is None and time.monotonic() < deadline and not temporaries:
            temporaries = [p for p in out.parent.glob(".rec.h5.tmp-*")] if out.parent.is_dir() else []
            time.sleep(0.02)
        assert temporaries and proc.poll() is None, "the simulation ended before it could be terminated"
        time.sleep(0.3)  # inside the simulation, the temporary file growing
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if ln.strip()]
    assert proc.returncode == 143, err[-3000:]
    assert lines[-1] == "simspad: terminated" and "Traceback" not in err, err[-3000:]
    assert os.listdir(out.parent) == [], os.listdir(out.parent)  # neither the temporary nor a partial recording
