"""dftc-mujoco: distributed fault-tolerant control of robot teams on MuJoCo physics.

Implements Arrichiello, Marino & Pierri (2017), *Distributed Fault-Tolerant
Control for Networked Robots in the Presence of Recoverable/Unrecoverable
Faults and Reactive Behaviors*, Frontiers in Robotics and AI.

The public API (imported lazily, so ``import dftc_mujoco`` stays cheap and
the OpenGL backend can still be chosen before MuJoCo is imported):

* :func:`load_scenario`, :class:`Scenario` - scenarios from TOML, dicts or code;
* :class:`Simulation`, :class:`Snapshot`, :func:`simulate` - run and step;
* :class:`RunResult`, :func:`open_run` - records of a run, saved or in memory;
* :mod:`dftc_mujoco.blocks.paper` - the paper's onboard blocks, to subclass;
* :func:`check_locality` - does a block set use only what each robot may know?
"""

import os as _os

# MuJoCo reads MUJOCO_GL when it is imported: default to EGL (Mesa renders on
# the CPU of a headless machine) unless the user chose a backend already.
_os.environ.setdefault("MUJOCO_GL", "egl")
if _os.environ["MUJOCO_GL"].lower() == "egl":
    _os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

__version__ = "0.2.0"

# numba's cache forgets that a compiled caller holds its callees' old code: empty it when
# any source changed (a stale cache crashed runs after an update in place)
from .runtime import numba_cache as _numba_cache

_numba_cache.refresh(_numba_cache.Path(__file__).parent)
_cache_note = _numba_cache.unwritable_note(_numba_cache.Path(__file__).parent)
if _cache_note is not None:  # said once, at import
    import warnings as _warnings

    _warnings.warn(_cache_note, stacklevel=2)

_API = {
    "load_scenario": "scenario",
    "Scenario": "scenario",
    "Simulation": "closed_loop.loop",
    "Snapshot": "closed_loop.loop",
    "simulate": "closed_loop.loop",
    "RunResult": "reporting.results",
    "open_run": "reporting.results",
    "check_locality": "onboard.execution.locality",
}

__all__ = [*_API, "__version__"]


def __getattr__(name: str):
    if name in _API:
        import importlib

        return getattr(importlib.import_module(f".{_API[name]}", __name__), name)
    raise AttributeError(f"module 'dftc_mujoco' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
