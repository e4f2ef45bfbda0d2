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

setup(
    packages=[*find_namespace_packages(include=["simspad", "simspad.*"], exclude=["*.__pycache__"]),
              *(f"{PACKAGED}.{name}" for name in BUNDLED)],
    package_dir={f"{PACKAGED}.{name}": name for name in BUNDLED},
    # specs: *.toml; a scene: <name>/scene.toml + scene.py (or .xml and its files); trajectories: .toml, .csv, .txt
    package_data={f"{PACKAGED}.datasets": ["*.toml"], f"{PACKAGED}.scenes": ["*/*"],
                  f"{PACKAGED}.trajectories": ["*"]},
)
