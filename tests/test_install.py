"""SimSPAD installed finds its bundled specs, scenes and trajectories from any working directory.

The bundled data lives at the repository root (``scenes/``, ``trajectories/``, ``datasets/``); setup.py maps it
into the wheel as ``simspad/_data/``. Three installs are checked, each run from a folder that is not the source:

- the wheel (``pip install .``) installed with ``--target`` and put first on ``PYTHONPATH``;
- the same wheel installed into a fresh virtual environment (``python -m venv --system-site-packages``: the heavy
  dependencies come from this environment), run with that environment's own ``python`` and no ``PYTHONPATH``;
- an editable install (``pip install -e .``) into another fresh virtual environment.

All build from a copy of this checkout's files (so nothing is written into the checkout and the editable install
is seen to take its data from its own source folder) without network access: ``--no-build-isolation`` takes
setuptools and wheel from the running environment. Users name the data exactly as in a checkout: ``mini``,
``office``, ``office_handheld_pan.toml``, and a recording stores a bundled trajectory as ``../trajectories/X``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BUNDLED = ("datasets", "scenes", "trajectories")

pytestmark = pytest.mark.slow

#: Printed by a child process: where its simspad and data are, what it lists, what a recording stores.
_REPORT = """
import json, simspad, simspad.bundled as b
from simspad.scenes.library import list_scenes
from simspad.dataset.spec import default_spec_path
from simspad.dataset.spec_validation import load_spec
from simspad.dataset.plan import make_plan
plan = make_plan(load_spec(default_spec_path()), "2025-01-01T00:00:00Z")
print(json.dumps({"package": simspad.__file__, "data_root": str(b.DATA_ROOT), "specs": b.builtin_spec_names(),
                  "scenes": {s.name: str(s.default_trajectory) for s in list_scenes()},
                  "pan": str(b.find_trajectory("office_handheld_pan.toml")),
                  "stored": sorted({dict(r.metadata)["trajectory"] for r in plan.recordings})}))
"""


def _source_files() -> list[Path]:
    """The checkout's files as git sees them (tracked, and new ones not ignored); else all but build outputs."""
    listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=REPO,
                            capture_output=True, timeout=60)
    if listed.returncode == 0:
        return [Path(name) for name in listed.stdout.decode().split("\0") if name and (REPO / name).is_file()]
    skip = {".git", "build", "dist", "output", ".venv", ".venvs", "__pycache__"}
    return [p.relative_to(REPO) for p in REPO.rglob("*")
            if p.is_file() and not skip & set(p.relative_to(REPO).parts) and ".egg-info" not in str(p)]


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    """A copy of this checkout's source files, to build and install from."""
    root = tmp_path_factory.mktemp("source") / "simspad-src"
    for rel in _source_files():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / rel, root / rel)
    return root


@pytest.fixture(scope="module")
def wheel(source, tmp_path_factory) -> Path:
    wheels = tmp_path_factory.mktemp("wheels")
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                            "-w", str(wheels), str(source)], capture_output=True, text=True, timeout=300)
    if build.returncode != 0 and "No module named" in build.stderr:
        pytest.skip(f"cannot build a wheel here: {build.stderr.strip().splitlines()[-1]}")
    assert build.returncode == 0, build.stderr
    (path,) = wheels.glob("simspad-*.whl")
    return path


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory) -> Path:
    site = tmp_path_factory.mktemp("site")
    install = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site),
                              str(wheel)], capture_output=True, text=True, timeout=300)
    assert install.returncode == 0, install.stderr
    return site


def _venv(root: Path) -> Path:
    """A fresh virtual environment seeing this one's packages; its python."""
    made = subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(root)], capture_output=True,
                          text=True, timeout=300)
    assert made.returncode == 0, made.stderr
    return root / "bin" / "python"


def _venv_pip_install(python: Path, *args: str) -> None:
    # --force-reinstall: a simspad of the same version seen in the base environment (an editable checkout) is not
    # "already satisfied" here; pip installs into the venv and leaves the base environment's alone.
    done = subprocess.run([str(python), "-m", "pip", "install", "--no-deps", "--no-build-isolation",
                           "--force-reinstall", "-q", *args], capture_output=True, text=True, timeout=300,
                          env=_env_without_pythonpath())
    assert done.returncode == 0, done.stderr


def _env_without_pythonpath() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}


@pytest.fixture(scope="module")
def wheel_venv(wheel, tmp_path_factory) -> Path:
    python = _venv(tmp_path_factory.mktemp("venv") / "wheel")
    _venv_pip_install(python, str(wheel))
    return python


@pytest.fixture(scope="module")
def editable_venv(source, tmp_path_factory) -> Path:
    python = _venv(tmp_path_factory.mktemp("venv") / "editable")
    _venv_pip_install(python, "-e", str(source))
    return python


def _report(python: Path, cwd: Path, env: dict[str, str]) -> dict:
    out = subprocess.run([str(python), "-c", _REPORT], cwd=cwd, env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def _cli(python: Path, cwd: Path, env: dict[str, str], *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(python), "-m", "simspad.cli", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=300)


def _check_finds_the_bundled_data(report: dict, package_root: Path, data_root: Path) -> None:
    package_root, data_root = package_root.resolve(), data_root.resolve()
    assert Path(report["package"]).is_relative_to(package_root)
    assert Path(report["data_root"]) == data_root
    assert report["specs"] == ["mini", "simspad"]
    assert sorted(report["scenes"]) == ["fan", "office", "piano", "plant", "siemens-star"]
    assert report["scenes"]["office"] == str(data_root / "trajectories" / "office.toml")
    assert report["pan"] == str(data_root / "trajectories" / "office_handheld_pan.toml")
    # what the mini recordings store: the same string as in a checkout, wherever the data sits
    assert report["stored"] == ["../trajectories/fan.toml", "../trajectories/office_handheld_pan.toml",
                                "../trajectories/piano_fast_orbit.toml", "../trajectories/plant_handheld_pan.toml",
                                "../trajectories/siemens-star.toml"]


def _check_the_commands_name_it_as_in_a_checkout(python: Path, cwd: Path, env: dict[str, str]) -> None:
    scenes = _cli(python, cwd, env, "scenes")
    assert scenes.returncode == 0, scenes.stderr
    assert "trajectories/office.toml" in scenes.stdout and "siemens-star" in scenes.stdout
    info = _cli(python, cwd, env, "info", "mini")
    assert info.returncode == 0, info.stderr
    assert "trajectory trajectories/office_handheld_pan.toml" in info.stdout
    (cwd / "mine.toml").write_text('name = "mine"\nlux = [10]\n[[sequences]]\nscene = "office"\n'
                                   'trajectory = "office_handheld_pan.toml"\nduration_s = 0.01\n'
                                   'resolution = [16, 12]\n')
    mine = _cli(python, cwd, env, "info", "mine.toml")
    assert mine.returncode == 0, mine.stderr
    assert "trajectory trajectories/office_handheld_pan.toml" in mine.stdout


def test_the_wheel_carries_every_bundled_file_byte_for_byte(wheel):
    with zipfile.ZipFile(wheel) as archive:
        names = {n for n in archive.namelist() if n.startswith("simspad/_data/")}
        shipped = {n.removeprefix("simspad/_data/"): archive.read(n) for n in names}
    tracked = {p.as_posix(): (REPO / p).read_bytes() for p in _source_files() if p.parts[0] in BUNDLED}
    assert shipped.keys() == tracked.keys()
    assert shipped == tracked
    assert {"datasets/mini.toml", "scenes/office/scene.py", "trajectories/office_handheld_pan.toml"} <= tracked.keys()


def test_wheel_imports_from_its_install_folder(installed, tmp_path):
    env = {**os.environ, "PYTHONPATH": str(installed)}
    report = _report(Path(sys.executable), tmp_path, env)
    _check_finds_the_bundled_data(report, installed, installed / "simspad" / "_data")


def test_wheel_describes_the_embedded_default_spec_from_another_directory(installed, tmp_path):
    out = _cli(Path(sys.executable), tmp_path, {**os.environ, "PYTHONPATH": str(installed)}, "info", "mini")
    assert out.returncode == 0, out.stderr
    assert "mini" in out.stdout and "office" in out.stdout


def test_wheel_renders_a_builtin_scene_on_its_bundled_trajectory(installed, tmp_path):
    out = _cli(Path(sys.executable), tmp_path, {**os.environ, "PYTHONPATH": str(installed)}, "render", "office",
               "--duration", "0.002", "--resolution", "16x12", "--spp", "1", "--out", "render")
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "render" / "timeline.json").is_file()
    assert not (REPO / "render").exists()


def test_pip_install_into_a_fresh_venv_finds_the_data_from_anywhere(wheel_venv, tmp_path):
    env = _env_without_pythonpath()
    site = Path(subprocess.run([str(wheel_venv), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               capture_output=True, text=True, env=env, timeout=60).stdout.strip())
    report = _report(wheel_venv, tmp_path, env)
    _check_finds_the_bundled_data(report, site, site / "simspad" / "_data")
    _check_the_commands_name_it_as_in_a_checkout(wheel_venv, tmp_path, env)


def test_editable_install_finds_the_data_of_its_source_folder_from_anywhere(editable_venv, source, tmp_path):
    env = _env_without_pythonpath()
    report = _report(editable_venv, tmp_path, env)
    _check_finds_the_bundled_data(report, source / "simspad", source)
    _check_the_commands_name_it_as_in_a_checkout(editable_venv, tmp_path, env)
