"""OpenGL backend for offscreen rendering (``MUJOCO_GL``).

MuJoCo reads ``MUJOCO_GL`` once, when ``mujoco`` is imported, so the backend
must be chosen before that: :mod:`dftc_mujoco` sets ``egl`` as the default on
import (Mesa's software EGL renders on the CPU of a machine with no display
and no GPU), and the command-line tools call :func:`select` before they import
anything that imports mujoco.
"""

from __future__ import annotations

import os
import sys

from ..errors import RenderError

BACKENDS = ("egl", "osmesa", "glfw")
DEFAULT = "egl"

HINTS = {
    "egl": "install an EGL driver: on Debian/Ubuntu `apt-get install libegl1 libegl-mesa0` "
    "(Mesa, renders on the CPU) or the NVIDIA driver",
    "osmesa": "install OSMesa: on Debian/Ubuntu `apt-get install libosmesa6`",
    "glfw": "GLFW needs a display (X11 or Wayland, DISPLAY set); on a headless machine "
    "use --gl egl or --gl osmesa",
}


def select(backend: str | None) -> str:
    """Make ``backend`` (or the current ``MUJOCO_GL``, or egl) the one mujoco will use."""
    wanted = (backend or os.environ.get("MUJOCO_GL") or DEFAULT).lower()
    if wanted not in BACKENDS:
        where = "--gl" if backend else "MUJOCO_GL in the environment"
        raise RenderError(
            f"{where}: expected one of {', '.join(BACKENDS)}, got {wanted!r}"
            + ("" if backend else " (unset it for egl, or choose one with --gl)")
        )
    current = os.environ.get("MUJOCO_GL", "").lower()
    if "mujoco" in sys.modules and current and current != wanted:
        raise RenderError(
            f"--gl {wanted}: mujoco was already imported with MUJOCO_GL={current}; "
            f"set MUJOCO_GL={wanted} in the environment instead"
        )
    os.environ["MUJOCO_GL"] = wanted
    if wanted in ("egl", "osmesa"):
        os.environ["PYOPENGL_PLATFORM"] = wanted  # PyOpenGL must load the same platform
    else:
        os.environ.pop("PYOPENGL_PLATFORM", None)
    return wanted


def active_backend() -> str:
    """The backend mujoco bound when it was imported ('' if it read no MUJOCO_GL)."""
    module = sys.modules.get("mujoco.rendering.classic.gl_context")
    if module is None:  # mujoco's rendering never finished importing
        return os.environ.get("MUJOCO_GL", "")
    return str(getattr(module, "_MUJOCO_GL", os.environ.get("MUJOCO_GL", "")))


def explain(exc: BaseException) -> RenderError:
    """A one-line :class:`RenderError` for a failed GL context, saying how to fix it."""
    backend = active_backend() or "glfw"
    reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    wanted = os.environ.get("MUJOCO_GL", "").lower()
    if wanted and wanted != backend:
        fix = (
            f"mujoco was imported before MUJOCO_GL={wanted} was set and bound "
            f"MUJOCO_GL={backend}: import dftc_mujoco before mujoco, or export "
            f"MUJOCO_GL={wanted} before starting Python"
        )
    else:
        fix = HINTS.get(backend, HINTS["glfw"])
    return RenderError(
        f"cannot create an offscreen OpenGL context with MUJOCO_GL={backend} ({reason}); "
        f"{fix}; or run with --no-video"
    )


def probe(width: int = 64, height: int = 64) -> None:
    """Render one frame of an empty model; raise :class:`RenderError` with a fix if it fails.

    A bare GL context is not enough: GLFW without a display, for one, creates
    a context object and only fails when MuJoCo's renderer needs it.
    """
    import warnings

    try:
        import mujoco

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # glfw warns before it fails; we explain once
            model = mujoco.MjModel.from_xml_string("<mujoco/>")
            with mujoco.Renderer(model, height, width) as renderer:
                renderer.update_scene(mujoco.MjData(model))
                renderer.render()
    except Exception as exc:  # the backends raise ImportError, RuntimeError, OSError, ...
        raise explain(exc) from None
