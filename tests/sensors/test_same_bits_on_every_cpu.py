"""One spec and seed give the same recording on every machine of a cluster, whatever BLAS kernel its CPU gets.

NumPy's matrix products go to OpenBLAS, which picks a kernel for the CPU at run time (``OPENBLAS_CORETYPE``
overrides the choice): summation order and fused multiply-adds differ between kernels, and so does the last bit
of a product. Luminance was once such a product, and an AVX-512 machine and an AVX2 machine simulated different
SPAD bits, events and ground truth from the same render. Each child process here is forced onto another kernel.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from simspad.io.render_dir import write_render_dir

#: OpenBLAS's AVX2 and AVX-512 kernels: their float32 products differ (its SSE3 and AVX kernels agree with the
#: AVX2 one). The AVX-512 kernel needs a CPU that has it.
CORE_TYPES = ("Haswell", "SkylakeX")


def _cpu_has_avx512() -> bool:
    try:
        return "avx512f" in Path("/proc/cpuinfo").read_text().split()
    except OSError:
        return False


pytestmark = pytest.mark.skipif(not _cpu_has_avx512(), reason="needs a CPU with AVX-512 to run both BLAS kernels")

_LUMINANCE_CHILD = r"""
import hashlib, json, sys
import numpy as np
from simspad.physics.radiometry import _rgb_to_y_weights, luminance_from_rgb
rgb = np.load(sys.argv[1])
digest = lambda a: hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()
print(json.dumps({"simspad": digest(luminance_from_rgb(rgb)), "blas": digest(rgb @ _rgb_to_y_weights())}))
"""


def _with_core(child_env: dict, core: str) -> dict:
    return {**child_env, "OPENBLAS_CORETYPE": core}


def _radiance(shape, seed: int) -> np.ndarray:
    """Linear RGB spread over four decades (every rounding of a weighted sum shows somewhere)."""
    return np.exp(np.random.default_rng(seed).normal(0.0, 2.0, shape)).astype(np.float32)


def test_luminance_is_the_same_under_every_blas_kernel(tmp_path, child_env):
    path = tmp_path / "rgb.npy"
    np.save(path, _radiance((64, 64, 3), 0))
    out = {core: json.loads(subprocess.run([sys.executable, "-c", _LUMINANCE_CHILD, str(path)], check=True,
                                           capture_output=True, text=True, env=_with_core(child_env, core)).stdout)
           for core in CORE_TYPES}
    if out[CORE_TYPES[0]]["blas"] == out[CORE_TYPES[1]]["blas"]:
        pytest.skip("this NumPy's BLAS gives one product under both kernels: nothing here tells them apart")
    assert out[CORE_TYPES[0]]["simspad"] == out[CORE_TYPES[1]]["simspad"]


def _dataset_digests(path) -> dict[str, str]:
    import hdf5plugin  # noqa: F401 - the SPAD bits' Zstandard filter

    digests = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                digests[name] = hashlib.sha256(np.ascontiguousarray(obj[()]).tobytes()).hexdigest()
        f.visititems(visit)
    return digests


@pytest.mark.slow
def test_recording_is_the_same_under_every_blas_kernel(tmp_path, simspad_cli):
    times = np.arange(5) * 1e-3
    render = write_render_dir(tmp_path / "render", times, _radiance((5, 12, 16, 3), 1)).parent
    files = {}
    for core in CORE_TYPES:
        files[core] = tmp_path / f"{core}.h5"
        env = {**_with_core(simspad_cli.env, core), "SOURCE_DATE_EPOCH": "1700000000"}  # the one attribute of time
        done = simspad_cli.run("simulate", render, "--lux", 100, "--out", files[core], env=env)
        assert done.returncode == 0, done.stderr
    first, second = (_dataset_digests(files[core]) for core in CORE_TYPES)
    assert {"spad/bits", "events/t", "frames/dn", "gt/flux"} <= set(first)
    assert [name for name in first if first[name] != second.get(name)] == []
    # attributes too (parameters, statistics of the drawn maps): the files are byte for byte the same
    assert files[CORE_TYPES[0]].read_bytes() == files[CORE_TYPES[1]].read_bytes()
