"""Seeing the motion: offscreen previews of a retarget beside its source skeleton.

* :mod:`.backend`: choosing the OpenGL backend (EGL or OSMesa when there is no display).
* :mod:`.skeleton`: the source skeleton placed like the character (same scale, floor, facing).
* :mod:`.scene`: one frame rendered with ``mujoco.Renderer``: character, skeleton, floor grid,
  planted contacts, a camera following the pelvis.
* :mod:`.output`: MP4/GIF streamed to ``imageio``, PNG contact sheets, frame labels.

This package imports nothing heavy: :mod:`.backend` must run before MuJoCo's first
import (``physmocap/__init__.py`` does so), so import the submodules directly.
"""
