"""Ctrl-C pressed twice during `generate` or `evaluate`: one line, exit 130, no traceback (issue 14, low).

A terminal sends SIGINT to the whole foreground process group: the driver and its pool workers. Before, workers
still importing numpy/scipy printed their own tracebacks, and the second press broke into the driver's clean-up.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from tests.helpers.evaluation_data import write_dataset


def _workers_started(pid: int) -> bool:
    try:
        return bool(Path(f"/proc/{pid}/task/{pid}/children").read_text().split())
    except OSError:
        return False


def _press_ctrl_c_twice(simspad_cli, *args, gap_s: float) -> subprocess.CompletedProcess:
    # Its own group, as in a terminal, with Ctrl-C's default action: a suite started as a background job (`&`
    # in a non-interactive shell) runs with SIGINT ignored, which children inherit and SimSPAD rightly keeps.
    proc = subprocess.Popen(simspad_cli.command(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env=simspad_cli.env, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while proc.poll() is None and not _workers_started(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.3)  # workers spawned, some still importing: where a Ctrl-C used to print their tracebacks
    assert proc.poll() is None, "the command ended before it could be interrupted"
    os.killpg(proc.pid, signal.SIGINT)
    time.sleep(gap_s)
    try:
        os.killpg(proc.pid, signal.SIGINT)
    except ProcessLookupError:  # the whole group already exited: a second press cannot land anywhere
        pass
    out, err = proc.communicate(timeout=120)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out.decode(), err.decode())


@pytest.fixture(scope="module")
def long_evaluation(tmp_path_factory) -> Path:
    """A dataset whose evaluation lasts seconds after its workers start: the session's shared one (two
    recordings) is scored in ~0.3 s once the workers have imported, so both presses could land after the command
    had returned, while the interpreter shuts down (its signal handlers reset: death by SIGINT, no line)."""
    # 96 recordings, 192 runs: ≈ 1.7 s of scoring on a fast machine (its forked workers start with no imports to
    # wait for), where 12 recordings were done 0.25 s after the workers started, before the first press landed
    luxes = tuple(float(f"{x:.3g}") for x in np.geomspace(1.0, 1000.0, 24))
    return write_dataset(tmp_path_factory.mktemp("interrupts") / "data", luxes=luxes,
                         sequences=("ramp", "slope", "step", "flat"))


@pytest.mark.parametrize("gap_s", [0.05, 0.5])
@pytest.mark.parametrize("command", ["generate", "evaluate"])
def test_double_ctrl_c_is_one_line(command, gap_s, tmp_path, simspad_cli, long_evaluation):
    if command == "generate":
        args = ("generate", "mini", "--out", tmp_path / "mini", "--workers", 2)
    else:
        args = ("evaluate", long_evaluation, "--out", tmp_path / "res")
    proc = _press_ctrl_c_twice(simspad_cli, *args, gap_s=gap_s)
    lines = [ln for ln in proc.stderr.replace("\r", "\n").splitlines() if ln.strip()]
    assert proc.returncode == 130, proc.stderr[-3000:]
    assert lines[-1] == "simspad: interrupted", proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr and "Error" not in proc.stderr, proc.stderr[-3000:]
    assert "resource_tracker" not in proc.stderr and "leaked" not in proc.stderr, proc.stderr[-3000:]


_KEYBOARD_INTERRUPT_FROM_A_TASK = r"""
import signal, sys
import simspad.cli.app as app

def run(**kwargs):  # the command ends with a KeyboardInterrupt that this process's handler did not raise
    raise KeyboardInterrupt

app.cli.main = run
code = app.main(["generate", "mini"])
print(code, signal.getsignal(signal.SIGINT) is signal.SIG_IGN)
"""


def test_interrupt_from_anywhere_leaves_sigint_ignored_to_the_end(child_env):
    """Whatever raised the KeyboardInterrupt, SIGINT stays ignored while the process exits. With Python's own
    handler put back, a second press during the exit (joining threads and pools) raised there, and Python ended
    the process by SIGINT after its one line: status −2, seen once in `test_double_ctrl_c_is_one_line`."""
    done = subprocess.run([os.sys.executable, "-c", _KEYBOARD_INTERRUPT_FROM_A_TASK], capture_output=True,
                          text=True, env=child_env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["130", "True"]
    assert done.stderr.strip().splitlines() == ["simspad: interrupted"]


_CTRL_C_WHILE_EXITING = r"""
import atexit, os, signal, sys, time
import simspad.cli.app as app

def press_ctrl_c():  # a Ctrl-C that lands after the command's work, while the interpreter exits
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.1)

atexit.register(press_ctrl_c)
app.cli.main = lambda **kwargs: None  # the command: done at once
sys.argv = ["simspad", "evaluate", "x"]
sys.exit(app.main())
"""


def test_ctrl_c_while_the_program_exits_is_ignored(child_env):
    """The command's work is done and the interpreter is exiting (joining its pools and threads) when Ctrl-C is
    pressed: the process ends with the command's own status and prints nothing. With Python's handler put back at
    the end of the command, the press raised in the exit: a traceback, or death by SIGINT with status −2 and no
    line (seen in `test_double_ctrl_c_is_one_line[evaluate-0.5]` when the evaluation finished before the press)."""
    done = subprocess.run([os.sys.executable, "-c", _CTRL_C_WHILE_EXITING], capture_output=True, text=True,
                          env=child_env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stderr == "", done.stderr
