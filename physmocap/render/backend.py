"""The OpenGL backend for offscreen rendering.

MuJoCo reads ``MUJOCO_GL`` when it creates its first rendering context.  With a
display (``DISPLAY`` or ``WAYLAND_DISPLAY``) GLFW works; without one, EGL
(``libegl1`` with a Mesa or vendor driver) or OSMesa (``libosmesa6``, software)
must be used.  :func:`ensure_backend` picks one before any context exists and
checks it by creating a tiny context, so a missing library is one clear error
naming the Debian package to install, never a traceback.
"""

from __future__ import annotations

import ctypes.util
import os

from ..errors import PhysmocapError

__all__ = ["RenderError", "choose_backend", "select_backend_env", "ensure_backend"]

#: Backend -> (shared library to look for, Debian package providing it).
BACKENDS = {"egl": ("EGL", "libegl1 libegl-mesa0"), "osmesa": ("OSMesa", "libosmesa6"), "glfw": ("glfw", "libglfw3")}


class RenderError(PhysmocapError):
    """Rendering is impossible here (no OpenGL backend)."""


def choose_backend() -> str | None:
    """The backend to use: ``MUJOCO_GL`` if set, else GLFW with a display, else the
    first of EGL and OSMesa whose library is installed; None if none is."""
    given = os.environ.get("MUJOCO_GL")
    if given:
        return given.lower()
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return "glfw"
    for name in ("egl", "osmesa"):
        if ctypes.util.find_library(BACKENDS[name][0]):
            return name
    return None


#: A ``MUJOCO_GL`` the user set whose library is missing (MuJoCo's import would fail on it).
_unusable: str | None = None


def select_backend_env() -> None:
    """Set ``MUJOCO_GL`` (if unset) to the backend :func:`choose_backend` picks, without
    importing MuJoCo: it must be set before MuJoCo's first import to take effect.

    A ``MUJOCO_GL=egl`` or ``osmesa`` whose library is not installed would make every
    ``import mujoco`` fail; it is set aside (and rendering then fails with a clear
    message naming the package) so that commands which do not render still work.
    """
    global _unusable
    given = (os.environ.get("MUJOCO_GL") or "").lower()
    if given in ("egl", "osmesa") and not ctypes.util.find_library(BACKENDS[given][0]):
        _unusable = given
        del os.environ["MUJOCO_GL"]
        return
    if not given:
        name = choose_backend()
        if name is not None and name != "glfw":
            os.environ["MUJOCO_GL"] = name


_checked: str | None = None


def _use_backend(name: str) -> None:
    """Point MuJoCo's renderer at the headless backend ``name``.

    MuJoCo reads ``MUJOCO_GL`` once, at its import; a program that imported ``mujoco``
    before ``physmocap`` got its default (GLFW, which needs a display), so the context
    class is replaced here when it is not the chosen one.
    """
    if name not in ("egl", "osmesa"):
        return
    import importlib
    import sys

    wanted = importlib.import_module(f"mujoco.{name}").GLContext
    for module in ("mujoco.rendering.classic.gl_context", "mujoco.gl_context"):
        loaded = sys.modules.get(module)
        if loaded is not None and getattr(loaded, "GLContext", wanted) is not wanted:
            loaded.GLContext = wanted


def ensure_backend() -> str:
    """Select and test the OpenGL backend; returns its name.

    Raises:
        RenderError: No backend works; the message names the Debian packages.
    """
    global _checked
    if _checked is not None:
        return _checked
    if _unusable is not None:
        raise RenderError(
            f"cannot render with MUJOCO_GL={_unusable}: its library is not installed; "
            f"install {BACKENDS[_unusable][1]} (Debian) or choose another backend with MUJOCO_GL=egl|osmesa"
        )
    name = choose_backend()
    hint = "install an OpenGL backend: apt-get install libegl1 libegl-mesa0 (or libosmesa6 and MUJOCO_GL=osmesa)"
    if name is None:
        raise RenderError(f"cannot render: no display and no EGL or OSMesa library found; {hint}")
    os.environ.setdefault("MUJOCO_GL", name)
    import mujoco

    try:
        _use_backend(os.environ["MUJOCO_GL"].lower())
    except Exception as exc:  # noqa: BLE001 - an unloadable backend is the same problem
        raise RenderError(
            f"cannot load the {name} OpenGL backend: {str(exc).splitlines()[0][:120]}; {hint}"
        ) from None

    try:
        model = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='.1'/></worldbody></mujoco>")
        with mujoco.Renderer(model, 8, 8) as renderer:
            renderer.render()
    except Exception as exc:  # noqa: BLE001 - any failure of the GL stack is the same problem
        pkg = BACKENDS.get(name, ("", hint))[1]
        raise RenderError(
            f"cannot render with MUJOCO_GL={os.environ.get('MUJOCO_GL')}: {str(exc).splitlines()[0][:120]}; "
            f"install {pkg} (Debian) or choose another backend with MUJOCO_GL=egl|osmesa"
        ) from None
    _checked = name
    return name
