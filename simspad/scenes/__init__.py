"""The scene model: the built-in scene library, users' Mitsuba scenes, and the procedural assets they use.

Nothing here imports the renderer; :mod:`simspad.render` loads what :func:`scene_dict_or_file` returns.
"""

from simspad.scenes.library import (
    SceneInfo,
    content_hash,
    list_scenes,
    resolve_scene,
    scene_dict_or_file,
)

__all__ = ["SceneInfo", "content_hash", "list_scenes", "resolve_scene", "scene_dict_or_file"]
