"""Worker-process plumbing (simspad/processes.py): cores from the CPU affinity, workers that die with their driver
and ignore Ctrl-C, and one home for all of it."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _alive(pid: int) -> bool:
    """True while ``pid`` runs (a zombie waiting for a reaper counts as dead)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="needs CPU affinity and at least two usable cores")
def test_available_cores_counts_the_cores_this_process_may_use(child_env):
    code = ("import os; from simspad.processes import available_cores; "
            "os.sched_setaffinity(0, {min(os.sched_getaffinity(0))}); print(available_cores(), os.cpu_count())")
    out = subprocess.run([sys.executable, "-c", code], env=child_env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    cores, machine = map(int, out.stdout.split())
    assert cores == 1 and machine >= 2  # taskset's one core, not the machine's count


_DRIVER = """
import concurrent.futures as cf, multiprocessing as mp, os, sys, time
from simspad.processes import die_with_parent_and_ignore_sigint
if __name__ == "__main__":
    pool = cf.ProcessPoolExecutor(1, mp_context=mp.get_context("spawn"), initializer=die_with_parent_and_ignore_sigint)
    print(pool.submit(os.getpid).result(), flush=True)
    time.sleep(60)
"""


def test_a_worker_ignores_ctrl_c_and_dies_with_its_driver(child_env, tmp_path):
    script = tmp_path / "driver.py"
    script.write_text(_DRIVER)
    driver = subprocess.Popen([sys.executable, str(script)], env=child_env, stdout=subprocess.PIPE, text=True)
    try:
        worker = int(driver.stdout.readline())
        os.kill(worker, signal.SIGINT)  # Ctrl-C is the driver's: the worker carries on
        time.sleep(0.5)
        assert _alive(worker)
        driver.kill()  # kill -9: no clean-up in the driver, so only the kernel can stop the worker
        driver.wait(timeout=30)
        deadline = time.monotonic() + 10
        while _alive(worker) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _alive(worker), "the pool worker outlived its killed driver"
    finally:
        driver.kill()
        driver.wait(timeout=30)


def test_process_plumbing_has_one_home():
    """Core counts, PR_SET_PDEATHSIG and the workers' SIGINT set-up are written in simspad/processes.py only."""
    plumbing = re.compile(r"\bcpu_count\(|\bsched_getaffinity\(|\.prctl\(|pthread_sigmask\(")
    elsewhere = [f"{path.relative_to(REPO)}:{n}" for path in sorted((REPO / "simspad").rglob("*.py"))
                 if path.name != "processes.py" or path.parent.name != "simspad"
                 for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1) if plumbing.search(line)]
    assert not elsewhere, f"process plumbing outside simspad/processes.py: {elsewhere}"
