"""kill -9 at random instants (docs/trust.md): a ``simspad evaluate`` or ``simspad export --to npz`` re-run into
its own earlier output folder and killed with SIGKILL at seeded random moments leaves the user's files there
untouched and no file of its own half-written under a final name; the next run completes and gives what an
uninterrupted run gives.

(``generate`` killed by SIGKILL and resumed to identical bytes: tests/dataset/test_generate.py.)
"""

from __future__ import annotations

import csv
import shutil
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from simspad.io.hashing import file_sha256

PRECIOUS = b"a user's own notes\n"
#: Columns of results.csv that measure this run's machine, not the result.
RUN_DEPENDENT = {"runtime_s"}


def _results(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as f:
        return [{k: v for k, v in row.items() if k not in RUN_DEPENDENT} for row in csv.DictReader(f)]


def _kill_at(simspad_cli, args, delay_s: float) -> int:
    proc = subprocess.Popen(simspad_cli.command(*args), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=simspad_cli.env, start_new_session=True)
    time.sleep(delay_s)
    if proc.poll() is None:
        proc.send_signal(signal.SIGKILL)
    return proc.wait(timeout=120)


def _final_files(out: Path) -> list[Path]:
    """Files under their final names (temporaries start with a dot, the lock and markers are bookkeeping)."""
    return [p for p in out.rglob("*") if p.is_file() and not any(part.startswith(".") for part in
                                                                    p.relative_to(out).parts)]


@pytest.mark.slow
def test_evaluate_killed_at_random_instants_keeps_user_files_and_resumes_to_the_same_results(
        simspad_cli, evaluation_dataset, tmp_path):
    data = Path(shutil.copytree(evaluation_dataset, tmp_path / "data"))
    reference = tmp_path / "reference"
    start = time.monotonic()
    ok = simspad_cli.run("evaluate", data, "--methods", "ni,qbp", "--out", reference)
    wall_s = time.monotonic() - start  # the kills land inside a run of this machine's speed now
    assert ok.returncode == 0, ok.stderr
    expected = _results(reference / "results.csv")
    out = tmp_path / "res"  # a results folder of an earlier run, with the user's notes beside the results
    assert simspad_cli.run("evaluate", data, "--methods", "ni,qbp", "--out", out).returncode == 0
    (out / "notes.txt").write_bytes(PRECIOUS)
    rng = np.random.default_rng(33)
    killed = 0
    for delay in rng.uniform(0.05, 0.9, 4) * wall_s:
        rc = _kill_at(simspad_cli, ("evaluate", data, "--methods", "ni,qbp", "--out", out), float(delay))
        killed += rc == -signal.SIGKILL
        assert (out / "notes.txt").read_bytes() == PRECIOUS
        if (out / "results.csv").exists():  # a results.csv under its final name is always a whole one
            assert _results(out / "results.csv") == expected
    assert killed >= 1, "no run was killed: the delays are too long for this machine"
    final = simspad_cli.run("evaluate", data, "--methods", "ni,qbp", "--out", out)
    assert final.returncode == 0, final.stderr
    assert _results(out / "results.csv") == expected
    assert (out / "notes.txt").read_bytes() == PRECIOUS
    assert not [p for p in out.rglob(".*.tmp-*")], "a killed run's temporary outlived the next run"


@pytest.mark.slow
def test_npz_export_killed_at_random_instants_keeps_user_files_and_resumes_to_the_same_bytes(
        simspad_cli, evaluation_dataset, tmp_path):
    rec = next(p for p in sorted((evaluation_dataset / "recordings").rglob("*.h5")) if not p.name.startswith("."))
    reference = tmp_path / "reference"
    start = time.monotonic()
    assert simspad_cli.run("export", rec, "--to", "npz", "--out", reference).returncode == 0
    wall_s = time.monotonic() - start
    want = {p.relative_to(reference).as_posix(): file_sha256(p) for p in _final_files(reference)}
    out = tmp_path / "npz"  # an earlier export, with the user's notes beside it
    assert simspad_cli.run("export", rec, "--to", "npz", "--out", out).returncode == 0
    (out / "notes.txt").write_bytes(PRECIOUS)
    rng = np.random.default_rng(34)
    for delay in rng.uniform(0.05, 0.9, 4) * wall_s:
        _kill_at(simspad_cli, ("export", rec, "--to", "npz", "--out", out), float(delay))
        assert (out / "notes.txt").read_bytes() == PRECIOUS
        for p in _final_files(out):  # every file under a final name is whole: the reference's bytes
            rel = p.relative_to(out).as_posix()
            assert rel == "notes.txt" or file_sha256(p) == want[rel], rel
    final = simspad_cli.run("export", rec, "--to", "npz", "--out", out)
    assert final.returncode == 0, final.stderr
    got = {p.relative_to(out).as_posix(): file_sha256(p) for p in _final_files(out)}
    assert got == {**want, "notes.txt": file_sha256(out / "notes.txt")}
