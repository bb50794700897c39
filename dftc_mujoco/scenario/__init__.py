"""Scenarios: TOML files turned into frozen, validated dataclasses.

A scenario is loaded by name (``scenarios/NAME.toml``) or by path, optionally
with dotted-key overrides (:func:`load_scenario`). Every problem is reported
in one :class:`~dftc_mujoco.errors.ScenarioError`, one line per problem in
file order, each naming the file, the key and what was expected. Robots are
numbered from 1 in the file (as in the paper) and from 0 inside the code.

A :class:`Scenario` built in code (``Scenario(...)``, ``dataclasses.replace``)
is validated exactly as a file is: :meth:`Scenario.to_dict` turns it back into
a TOML document, which goes through the same checks. :meth:`Scenario.to_toml`
writes that document as text.
"""

from __future__ import annotations

from ..core.mission import CentroidPath, Formation, Mission
from ..runtime.paths import SCENARIOS
from ..runtime.tomlcheck import N_DIM
from .model import (
    Scenario,
    _trusted,
    apply_overrides,
    dropped_faults,
    from_dict,
    load,
    load_scenario,
    resolve,
)
from .parts import (
    ACTUATOR_FAULTS,
    RADIO_FAULTS,
    SENSOR_FAULTS,
    Fault,
    Fdir,
    Gains,
    Network,
    Noise,
    Obstacle,
    Onboard,
    Physics,
    RadioFault,
    Supervision,
    Team,
)
from .readers import NAME_PATTERN, name_problem

__all__ = [
    "ACTUATOR_FAULTS",
    "NAME_PATTERN",
    "N_DIM",
    "RADIO_FAULTS",
    "SCENARIOS",
    "SENSOR_FAULTS",
    "CentroidPath",
    "Fault",
    "Fdir",
    "Formation",
    "Gains",
    "Mission",
    "Network",
    "Noise",
    "Obstacle",
    "Onboard",
    "Physics",
    "RadioFault",
    "Scenario",
    "Supervision",
    "Team",
    "_trusted",
    "apply_overrides",
    "dropped_faults",
    "from_dict",
    "load",
    "load_scenario",
    "name_problem",
    "resolve",
]
