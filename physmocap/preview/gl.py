"""An offscreen OpenGL context for :class:`mujoco.Renderer`, chosen automatically.

MuJoCo picks its OpenGL backend from ``MUJOCO_GL`` when ``mujoco`` is first
imported (GLFW by default, which needs a display).  Without a display and
without ``MUJOCO_GL``, :func:`select_backend` picks EGL, else OSMesa, whichever
library is installed, and points MuJoCo's renderer at it.  When neither is
there, or the context cannot be created, the error says which Debian package
to install.
"""

from __future__ import annotations

import ctypes.util
import importlib
import os

import mujoco

from ..errors import PhysmocapError

__all__ = ["BackendError", "has_display", "make_renderer", "select_backend"]

#: Headless backends in order of preference: (MUJOCO_GL value, library, Debian package).
HEADLESS = (("egl", "EGL", "libegl1"), ("osmesa", "OSMesa", "libosmesa6"))
_HINT = "install an OpenGL backend (Debian/Ubuntu: apt-get install libegl1, or libosmesa6) or set MUJOCO_GL"


class BackendError(PhysmocapError):
    """No OpenGL backend to render with."""


def has_display() -> bool:
    """True when a window can be opened (X11 or Wayland display set)."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def select_backend() -> str:
    """The OpenGL backend MuJoCo renders with: ``MUJOCO_GL`` if set, ``glfw``
    with a display, else the first installed headless backend (which is then
    installed as MuJoCo's ``GLContext``)."""
    chosen = os.environ.get("MUJOCO_GL", "").strip().lower()
    if chosen:
        return chosen
    if has_display():
        return "glfw"
    for name, library, _package in HEADLESS:
        if ctypes.util.find_library(library):
            os.environ["MUJOCO_GL"] = name
            os.environ.setdefault("PYOPENGL_PLATFORM", name)
            from mujoco.rendering.classic import gl_context

            try:
                gl_context.GLContext = importlib.import_module(f"mujoco.{name}").GLContext
            except Exception as exc:  # noqa: BLE001 - any failure to load the backend
                raise BackendError(f"cannot load the {name} OpenGL backend ({_first_line(exc)}); {_HINT}") from None
            return name
    raise BackendError(f"no display and no headless OpenGL library (EGL or OSMesa) found; {_HINT}")


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def make_renderer(model: mujoco.MjModel, width: int, height: int) -> mujoco.Renderer:
    """A :class:`mujoco.Renderer` of ``width`` x ``height`` pixels for ``model``.

    The model's offscreen buffer is enlarged to fit (the model is modified).
    """
    backend = select_backend()
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), int(width))
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), int(height))
    try:
        return mujoco.Renderer(model, height=int(height), width=int(width))
    except Exception as exc:  # noqa: BLE001 - GL failures come as many exception types
        raise BackendError(
            f"cannot create an OpenGL context with MUJOCO_GL={backend!r} ({_first_line(exc)}); {_HINT}"
        ) from None
