"""Every command README, docs and the examples' docstrings give on the output of README's main job runs.

README's main job writes ``output/mini`` (``simspad generate``). Here a shrunken mini — the bundled spec's fan
sequence only, at 16 × 12 px over 6 ms, both speeds and all three lux levels, so the recordings bear the names
the docs use (``recordings/fan/fan_100lx.h5``) — is generated into ``output/mini`` of a temporary working
directory, and each documented command that names ``output/mini`` is run there as written: the main job's own
evaluate and leaderboard, the method subset, ``--param``, ``simspad score`` (with a submission written as
docs/submission.md describes) and both examples. Commands that need what the main job does not make (a plugin
package, a benchmark's older revision) are listed in ``NOT_RUN`` with the test that covers them instead.
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from simspad.evaluate.protocol import evaluation_indices

REPO = Path(__file__).resolve().parents[1]
#: Documented commands on output/mini run elsewhere: what they need and where they are tested.
NOT_RUN = {
    "toy_gain": "the plugin package of docs/methods.md (tests/methods/test_params_and_plugins.py installs it)",
    "benchmarks/bench_evaluate.py": "an older revision to compare with (tests/test_benchmarks.py)",
}


def _documented_commands() -> list[str]:
    """Shell commands naming output/mini in README, docs/*.md and the examples' docstrings (one per line, the
    README's set-up line split at `&&`, comments dropped)."""
    texts = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md")), *sorted((REPO / "examples").glob("*.py"))]
    out = []
    for path in texts:
        for line in path.read_text(encoding="utf-8").splitlines():
            line = line.split("  #")[0].strip().strip("`")
            for part in line.split("&&"):
                part = part.strip()
                if "output/mini" in part and re.match(r"(simspad|python) ", part) and "|" not in part:
                    out.append(part)
    return sorted(set(out))


TINY_MINI = """
name = "mini"
seed = 20250101
output = "output/mini"
lux = [1, 100, 10000]
speed = [1, 16]

[[sequences]]
scene = "fan"
duration_s = 0.006
resolution = [16, 12]
spp = 4
max_flow_px = 1.0

[sensors.spad]
preset = "swissspad2"

[sensors.frames]
preset = "blackfly_s"
frame_rate_hz = 500
exposure_s = 0.001

[sensors.events]
preset = "prophesee_gen4"

[evaluation]
rate_hz = 1000
methods = []
"""


@pytest.fixture(scope="module")
def workdir(tmp_path_factory, simspad_cli) -> Path:
    cwd = tmp_path_factory.mktemp("readme")
    (cwd / "mini.toml").write_text(TINY_MINI)
    res = subprocess.run(simspad_cli.command("generate", "mini.toml"), cwd=cwd, env=simspad_cli.env,
                         capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stderr[-3000:]
    # my_method.h5 for `simspad score`, as docs/submission.md writes one: ground truth at the evaluation instants
    dataset = cwd / "output" / "mini"
    with h5py.File(cwd / "my_method.h5", "w") as f:
        f.attrs.update(format="simspad-submission", format_version=1, method="mymethod", label="MyMethod (E)",
                       sensors="E", absolute_scale=False, bandwidth_khz_per_pixel=0.05,
                       bandwidth_bits_per_pixel_s=1600.0)
        for rec in sorted((dataset / "recordings").rglob("*.h5")):
            with h5py.File(rec, "r") as r:
                idx = evaluation_indices(r["gt/t"][()], 1000.0)
                t, flux = r["gt/t"][()][idx], r["gt/flux"][()][idx]
            g = f.create_group(rec.relative_to(dataset).with_suffix("").as_posix())
            g.create_dataset("t", data=t)
            g.create_dataset("flux", data=np.asarray(flux, np.float32))
    return cwd


def test_the_docs_name_commands_on_the_main_jobs_output():
    commands = _documented_commands()
    assert any(c.startswith("simspad evaluate output/mini --out output/mini/results") for c in commands), commands
    assert any("examples/" in c for c in commands), commands


@pytest.mark.slow
@pytest.mark.parametrize("command", _documented_commands())
def test_documented_command_runs_on_the_main_jobs_output(command, workdir, simspad_cli):
    skip = [why for key, why in NOT_RUN.items() if key in command]
    if skip:
        pytest.skip(f"needs {skip[0]}")
    argv = shlex.split(command)
    if argv[0] == "simspad":
        argv = simspad_cli.command(*argv[1:])
    else:
        argv = [sys.executable, *argv[1:]]
        argv[1] = str(REPO / argv[1])
    if "leaderboard" in command and "results" in command:  # the leaderboard reads the results it names
        src = argv[argv.index("leaderboard") + 1] if "leaderboard" in argv else None
        if src and not (workdir / src).exists():
            needed = next(c for c in _documented_commands() if c.startswith("simspad evaluate") and src in c)
            prep = subprocess.run(simspad_cli.command(*shlex.split(needed)[1:]), cwd=workdir, env=simspad_cli.env,
                                  capture_output=True, text=True, timeout=900)
            assert prep.returncode == 0, prep.stderr[-3000:]
    res = subprocess.run(argv, cwd=workdir, env=simspad_cli.env, capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, f"{command}\n{res.stdout[-2000:]}\n{res.stderr[-3000:]}"
    assert "Traceback" not in res.stderr
