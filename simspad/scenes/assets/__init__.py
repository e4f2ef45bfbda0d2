"""Procedural assets of the built-in scenes: textures (numpy), meshes (numpy → ``mi.Mesh``) and dict helpers.

Everything here is deterministic (fixed seeds) and made at load time, cached in memory, so the repository
holds code, not image or mesh files.
"""
