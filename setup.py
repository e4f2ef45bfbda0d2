"""What goes into the wheel, beside pyproject.toml's metadata: the package and the bundled data at the root.

The built-in scenes, their trajectories and the dataset specs live at the repository root (``scenes/``,
``trajectories/``, ``datasets/``), beside ``simspad/``. setuptools' ``package_dir`` maps each of them to a data
package inside ``simspad`` (``simspad/_data/scenes``, ``simspad/_data/trajectories``, ``simspad/_data/datasets``),
so a wheel carries them in the package folder and :mod:`simspad.bundled` finds them there; a source checkout
(and an editable install, which runs the checkout's code) finds them at the root. pyproject.toml cannot express
this mapping next to automatic package discovery, hence this file.
"""

from setuptools import find_namespace_packages, setup

#: Folders at the repository root shipped as package data; simspad/bundled.py names the same three.
BUNDLED = ("datasets", "scenes", "trajectories")
#: Where they go inside the installed package (simspad.bundled.PACKAGED_DATA_DIR).
PACKAGED = "simspad._data"


def _packages_of(folder: str) -> list[str]:
    """The data package of a bundled folder and of each subfolder (a scene's folder, whose scene.py is listed as a
    module of a package: setuptools deprecates shipping .py files as loose data)."""
    subfolders = find_namespace_packages(where=folder, exclude=["__pycache__", "*.__pycache__"])
    return [f"{PACKAGED}.{folder}", *(f"{PACKAGED}.{folder}.{sub}" for sub in subfolders)]


DATA_PACKAGES = [package for folder in BUNDLED for package in _packages_of(folder)]

setup(
    packages=[*find_namespace_packages(include=["simspad", "simspad.*"], exclude=["*.__pycache__"]), *DATA_PACKAGES],
    # a subfolder's package maps below its folder's: scenes/office is simspad._data.scenes.office
    package_dir={f"{PACKAGED}.{folder}": folder for folder in BUNDLED},
    # every file: specs (.toml), a scene's scene.toml (and an .xml scene's files), trajectories (.toml, .csv, .txt)
    package_data={package: ["*"] for package in DATA_PACKAGES},
)
