"""The scene library: built-in scenes (the bundled ``scenes/``, :mod:`simspad.bundled`) and users' own Mitsuba 3
scenes.

A scene is a folder. Built-in scenes hold ``scene.toml`` (camera id, default trajectory, description, ids of
animated objects) and either ``scene.py`` exposing ``build() -> dict`` (for ``mi.load_dict``) or ``scene.xml``.
A user's scene is any folder holding one Mitsuba 3 ``.xml`` with a perspective sensor (or the path of that
``.xml``); an optional ``scene.toml`` beside it supplies the same fields as for built-in scenes.

A user's folder holding ``scene.py`` + ``scene.toml`` is Python code: it runs only when the user opts in
(``simspad --allow-python-scenes ...`` or ``SIMSPAD_ALLOW_PYTHON_SCENES=1``); otherwise it is refused, so naming
a downloaded folder never executes it. Built-in scenes are code shipped with SimSPAD and always run.

Relative ``default_trajectory`` paths resolve against the bundled data's root for built-in scenes (they point
into the bundled ``trajectories/``, beside ``scenes/``) and against the scene folder for users' scenes.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

from simspad.bundled import DATA_ROOT, SCENES_DIR
from simspad.errors import SimSpadError

_ASSETS_DIR = Path(__file__).resolve().parent / "assets"
#: Camera id assumed for a user's XML whose first perspective sensor has no id; the renderer then takes the
#: scene's first sensor.
DEFAULT_CAMERA_ID = "camera"
_PERSPECTIVE_TYPES = ("perspective", "thinlens")
#: Environment variable that opts in to running users' ``scene.py`` (set by ``--allow-python-scenes``, inherited
#: by worker processes).
ALLOW_PYTHON_SCENES_ENV = "SIMSPAD_ALLOW_PYTHON_SCENES"


def python_scenes_allowed() -> bool:
    """True when the user opted in to running their own ``scene.py`` scenes."""
    return os.environ.get(ALLOW_PYTHON_SCENES_ENV, "") == "1"


def _refuse_python_scene(folder: Path) -> None:
    raise SimSpadError("this scene folder holds scene.py, which is Python code; SimSPAD runs a user's Python scene "
                       f"only when asked: add --allow-python-scenes (simspad --allow-python-scenes COMMAND ...) or "
                       f"set {ALLOW_PYTHON_SCENES_ENV}=1 if you trust it, or give a Mitsuba .xml scene",
                       path=folder, field="scene")


@dataclass(frozen=True)
class SceneInfo:
    """Where a scene lives and how to animate it.

    Attributes
    ----------
    name : str
        Built-in name, or the user's folder (or file stem) name.
    folder : Path
        The scene folder (hashed by :func:`content_hash`).
    camera_id : str
        Id of the perspective sensor the renderer poses.
    default_trajectory : Path or None
        Trajectory used when none is given.
    description : str
        One line for ``simspad scenes``.
    objects : tuple of str
        Ids of shapes that trajectory objects animate.
    source : Path or None
        The ``scene.py`` builder or the ``.xml`` file the renderer loads.
    builtin : bool
        True for scenes shipped in the bundled ``scenes/``.
    """

    name: str
    folder: Path
    camera_id: str
    default_trajectory: Path | None
    description: str
    objects: tuple[str, ...] = ()
    source: Path | None = field(default=None, compare=False)
    builtin: bool = False


def builtin_scene_names() -> list[str]:
    """Names of the built-in scenes (folders of the bundled ``scenes/`` holding a ``scene.toml``), sorted."""
    if not SCENES_DIR.is_dir():
        return []
    return sorted(p.name for p in SCENES_DIR.iterdir() if (p / "scene.toml").is_file())


def list_scenes() -> list[SceneInfo]:
    """All built-in scenes, sorted by name."""
    return [_builtin_info(name) for name in builtin_scene_names()]


def resolve_scene(name_or_path) -> SceneInfo:
    """Find a scene by built-in name, by a user's scene folder, or by the path of a Mitsuba ``.xml`` file.

    Raises
    ------
    SimSpadError
        Unknown name or missing path (naming it and listing the built-in scenes), or a folder/XML that is
        not a usable Mitsuba scene.
    """
    if isinstance(name_or_path, SceneInfo):
        return name_or_path
    text = str(name_or_path)
    if text in builtin_scene_names() and not Path(text).exists():
        return _builtin_info(text)
    path = Path(text).expanduser()
    if path.is_dir():
        if (path / "scene.py").is_file() and (path / "scene.toml").is_file():
            builtin = path.resolve().parent == SCENES_DIR.resolve()
            if not builtin and not python_scenes_allowed():
                _refuse_python_scene(path)
            return _folder_info(path, builtin=builtin)
        return _user_info(_find_xml(path), name=path.resolve().name)
    if path.is_file():
        if path.suffix.lower() != ".xml":
            raise SimSpadError("expected a built-in scene name, a scene folder or a Mitsuba .xml file",
                               path=path, field="scene")
        stem = path.stem if path.stem != "scene" else path.resolve().parent.name
        return _user_info(path, name=stem)
    names = ", ".join(builtin_scene_names()) or "(none)"
    raise SimSpadError(f"unknown scene {text!r}: not a built-in scene ({names}) nor an existing folder or .xml file",
                       field="scene")


def scene_dict_or_file(info: SceneInfo) -> dict | Path:
    """What the renderer loads: ``build()``'s dict (for ``mi.load_dict``) or the XML path (for ``mi.load_file``).

    A Mitsuba variant must be set before calling this for a ``scene.py`` scene (``build()`` creates Mitsuba
    objects such as ``mi.Bitmap``). The returned dict is fresh on each call; procedural assets are cached in
    memory by :mod:`simspad.scenes.assets`.
    """
    info = resolve_scene(info)
    if info.source is None:
        raise SimSpadError("scene has neither scene.py nor an .xml file", path=info.folder, field="scene")
    if info.source.suffix == ".py":
        if not info.builtin and not python_scenes_allowed():
            _refuse_python_scene(info.folder)
        module = _load_builder(info.source)
        build = getattr(module, "build", None)
        if not callable(build):
            raise SimSpadError("scene.py must define build() -> dict", path=info.source, field="build")
        scene = build()
        if not isinstance(scene, dict) or scene.get("type") != "scene":
            raise SimSpadError("build() must return a Mitsuba scene dict with type 'scene'",
                               path=info.source, field="build")
        return scene
    return info.source


def content_hash(info: SceneInfo) -> str:
    """SHA-256 (hex) over the scene folder's files in sorted order: relative path and bytes of each.

    Built-in scenes also hash the procedural asset generators (``simspad/scenes/assets``), since their textures
    and meshes are made at load time. ``__pycache__`` and hidden files are skipped.
    """
    info = resolve_scene(info)
    digest = hashlib.sha256()
    roots = [("scene", info.folder)]
    if info.builtin and _ASSETS_DIR.is_dir():
        roots.append(("assets", _ASSETS_DIR))
    for label, root in roots:
        for path in sorted(_hashable_files(root)):
            rel = path.relative_to(root).as_posix()
            digest.update(f"{label}/{rel}\0".encode())
            with open(path, "rb") as fh:
                for block in iter(lambda: fh.read(1 << 20), b""):
                    digest.update(block)
            digest.update(b"\0")
    return digest.hexdigest()


# --------------------------------------------------------------------------------------------- internals


def _hashable_files(root: Path):
    for path in root.rglob("*"):
        rel = path.relative_to(root).parts
        if any(part.startswith(".") or part == "__pycache__" for part in rel):
            continue
        if path.is_file():
            yield path


def _read_toml(path: Path) -> dict:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise SimSpadError(f"malformed TOML: {exc}", path=path) from None


def _meta_fields(meta: dict, toml_path: Path, base: Path) -> dict:
    """Validate the fields of a ``scene.toml``; relative trajectory paths resolve against ``base``."""
    out = {}
    for key in ("camera_id", "description", "default_trajectory"):
        if key in meta and not isinstance(meta[key], str):
            raise SimSpadError(f"expected a string, got {type(meta[key]).__name__}", path=toml_path, field=key)
    if "camera_id" in meta:
        out["camera_id"] = meta["camera_id"]
    if "description" in meta:
        out["description"] = meta["description"]
    if meta.get("default_trajectory"):
        traj = Path(meta["default_trajectory"])
        traj = traj if traj.is_absolute() else base / traj
        if not traj.is_file():
            raise SimSpadError(f"default trajectory {str(traj)!r} does not exist", path=toml_path,
                               field="default_trajectory")
        out["default_trajectory"] = traj
    if "objects" in meta:
        objs = meta["objects"]
        if not isinstance(objs, list) or not all(isinstance(o, str) for o in objs):
            raise SimSpadError("expected a list of shape ids (strings)", path=toml_path, field="objects")
        for i, o in enumerate(objs):
            if not o.strip():  # an empty id matches no shape (Mitsuba gives unnamed shapes generated ids)
                raise SimSpadError(f"entry {i} is an empty shape id (expected the id of a shape in the scene)",
                                   path=toml_path, field="objects")
        out["objects"] = tuple(objs)
    return out


def _builtin_info(name: str) -> SceneInfo:
    return _folder_info(SCENES_DIR / name, builtin=True)


def _folder_info(folder: Path, *, builtin: bool) -> SceneInfo:
    toml_path = folder / "scene.toml"
    meta = _meta_fields(_read_toml(toml_path), toml_path, DATA_ROOT if builtin else folder)
    if (folder / "scene.py").is_file():
        source = folder / "scene.py"
    else:
        source = _find_xml(folder)
    return SceneInfo(name=folder.name, folder=folder.resolve(), camera_id=meta.get("camera_id", DEFAULT_CAMERA_ID),
                     default_trajectory=meta.get("default_trajectory"), description=meta.get("description", ""),
                     objects=meta.get("objects", ()), source=source.resolve(), builtin=builtin)


def _find_xml(folder: Path) -> Path:
    """The folder's scene file: ``scene.xml`` if present, else its only top-level ``.xml``."""
    if (folder / "scene.xml").is_file():
        return folder / "scene.xml"
    xmls = sorted(p for p in folder.glob("*.xml") if p.is_file())
    if not xmls:
        raise SimSpadError("scene folder holds no Mitsuba .xml file (nor scene.py + scene.toml)",
                           path=folder, field="scene")
    if len(xmls) > 1:
        names = ", ".join(p.name for p in xmls)
        raise SimSpadError(f"scene folder holds several .xml files ({names}); pass the path of one of them",
                           path=folder, field="scene")
    return xmls[0]


def _first_perspective_sensor_id(xml_path: Path) -> str:
    """Id of the first perspective (or thin-lens) sensor; :data:`DEFAULT_CAMERA_ID` if it has none."""
    try:
        root = ET.parse(xml_path).getroot()
    except ET.ParseError as exc:
        raise SimSpadError(f"malformed XML: {exc}", path=xml_path) from None
    if root.tag != "scene":
        raise SimSpadError(f"root element is <{root.tag}>, expected <scene>", path=xml_path, field="scene")
    for element in root.iter():
        if element.get("id") is not None and not element.get("id").strip():
            raise SimSpadError(f"<{element.tag} type=\"{element.get('type', '')}\"> has an empty id (give it a "
                               "name, or leave the id attribute out)", path=xml_path, field=f"{element.tag}.id")
    for sensor in root.iter("sensor"):
        if sensor.get("type") in _PERSPECTIVE_TYPES:
            return sensor.get("id") or DEFAULT_CAMERA_ID
    raise SimSpadError("the scene has no perspective sensor (<sensor type=\"perspective\">)", path=xml_path,
                       field="sensor")


def _user_info(xml_path: Path, *, name: str) -> SceneInfo:
    xml_path = xml_path.resolve()
    folder = xml_path.parent
    camera_id = _first_perspective_sensor_id(xml_path)
    meta = {}
    toml_path = xml_path.parent / "scene.toml"
    if toml_path.is_file():
        meta = _meta_fields(_read_toml(toml_path), toml_path, toml_path.parent)
    return SceneInfo(name=name, folder=folder, camera_id=meta.get("camera_id", camera_id),
                     default_trajectory=meta.get("default_trajectory"),
                     description=meta.get("description", f"user scene {xml_path.name}"),
                     objects=meta.get("objects", ()), source=xml_path, builtin=False)


_BUILDERS: dict[tuple[str, int], object] = {}


def _load_builder(path: Path):
    """Import a ``scene.py`` by path (cached per file and modification time)."""
    key = (str(path), path.stat().st_mtime_ns)
    if key not in _BUILDERS:
        spec = importlib.util.spec_from_file_location(f"simspad_scene_{path.parent.name.replace('-', '_')}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        _BUILDERS[key] = module
    return _BUILDERS[key]
