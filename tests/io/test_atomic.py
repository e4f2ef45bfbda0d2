"""Output safety of every writer: special files and links are never replaced, a full disk leaves nothing behind.

The full disk is real, not mocked: the child process runs under a file-size limit (``RLIMIT_FSIZE``, SIGXFSZ
ignored), so the kernel fails HDF5's writes and closes with EFBIG exactly where ENOSPC would strike.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from simspad.errors import SimSpadError
from simspad.io.atomic import atomic_path, check_output_path, remove_stale_temporaries, temporary_sibling
from simspad.io.recording import RecordingWriter


def _specials(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    target = tmp_path / "precious.png"
    target.write_bytes(b"keep")
    link = tmp_path / "link.png"
    link.symlink_to(target)
    sock_path = tmp_path / "sock"
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(sock_path))
    return {"a FIFO": fifo, "a symbolic link": link, "a socket": sock_path}, target, sock


def test_special_files_and_links_are_refused_by_every_writer(tmp_path):
    specials, target, sock = _specials(tmp_path)
    try:
        for what, path in specials.items():
            word = "symbolic link" if "link" in what else what
            with pytest.raises(SimSpadError, match=word):
                with atomic_path(path) as tmp:
                    tmp.write_bytes(b"png")
            with pytest.raises(SimSpadError, match=word):
                with RecordingWriter(path, {}) as w:
                    w.write_dataset("x", np.zeros(3))
        assert target.read_bytes() == b"keep" and (tmp_path / "link.png").is_symlink()
        assert os.path.exists(tmp_path / "fifo") and not [p for p in tmp_path.iterdir() if ".tmp-" in p.name]
        (tmp_path / "dir").mkdir()
        with pytest.raises(SimSpadError, match="is a directory; refusing to replace it with a file"):
            RecordingWriter(tmp_path / "dir", {}).__enter__()
        with pytest.raises(SimSpadError, match="is a regular file; refusing to replace it with a directory"):
            check_output_path(target, kind="dir")
    finally:
        sock.close()


def test_stale_temporaries_of_dead_processes_are_removed(tmp_path):
    final = tmp_path / "rec.h5"
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    stale = final.with_name(f".rec.h5.tmp-{int(dead.stdout)}-0123abcd")
    stale.write_bytes(b"x" * 100)
    mine = temporary_sibling(final)
    mine.write_bytes(b"y")
    assert remove_stale_temporaries(final) == [stale]
    assert not stale.exists() and mine.exists()  # a live writer's temporary stays


_FULL_DISK_CHILD = textwrap.dedent("""
    import resource, signal, sys
    import numpy as np
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, 200_000))
    import os
    from simspad.errors import SimSpadError
    from simspad.io.recording import RecordingWriter
    from simspad.io.recording.writer import hdf5_close_failed
    try:
        with RecordingWriter(sys.argv[1], {"lux": 1.0}) as w:
            a = w.append_dataset("spad/bits", (64, 64), np.uint8, chunk_rows=16)
            for _ in range(int(sys.argv[2])):
                a.append(np.ones((16, 64, 64), np.uint8))
    except SimSpadError as exc:
        print(exc.format(), flush=True)
        os._exit(2) if hdf5_close_failed() else sys.exit(2)
""")


@pytest.mark.parametrize("n_blocks", [3, 40])  # the limit struck at close (blocks flushed then) / while appending
def test_full_disk_leaves_no_file_and_one_line(tmp_path, child_env, n_blocks):
    out = tmp_path / "rec.h5"
    proc = subprocess.run([sys.executable, "-c", _FULL_DISK_CHILD, str(out), str(n_blocks)], capture_output=True,
                          text=True, env=child_env, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "the disk is full (filesystem mounted at" in proc.stdout and str(out) in proc.stdout
    assert "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == []  # neither the final name nor the temporary


def test_full_disk_in_simulate_is_one_line(tmp_path, simspad_cli):
    from simspad.io.render_dir import write_render_dir

    rng = np.random.default_rng(0)
    frames = [rng.random((48, 64, 3), dtype=np.float32) for _ in range(3)]
    render = write_render_dir(tmp_path / "render", np.array([0.0, 0.005, 0.01]), frames).parent
    out = tmp_path / "out" / "rec.h5"
    (tmp_path / "out").mkdir()
    cmd = ("import resource, signal, sys; signal.signal(signal.SIGXFSZ, signal.SIG_IGN); "
           "resource.setrlimit(resource.RLIMIT_FSIZE, (300_000, 300_000)); "
           "from simspad.cli.app import main; sys.exit(main(sys.argv[1:]))")
    proc = subprocess.run([sys.executable, "-c", cmd, "simulate", str(render), "--lux", "100", "--sensors", "spad",
                           "--out", str(out)], capture_output=True, text=True, env=simspad_cli.env, timeout=300)
    assert proc.returncode == 2, proc.stderr[-2000:]  # not 139: HDF5 is not left to crash at exit
    lines = proc.stderr.strip().splitlines()
    assert lines[-1].startswith("simspad: error: ") and "the disk is full" in lines[-1], proc.stderr[-2000:]
    # h5py itself may print one C-level "ObjectID._dealloc" traceback as the failed write unwinds (written
    # by Cython straight to stderr); nothing of SimSPAD's own code, and not the 12 of before.
    assert "simspad/" not in proc.stderr.replace(str(tmp_path), "") and proc.stderr.count("Traceback") <= 1
    assert list((tmp_path / "out").iterdir()) == []
