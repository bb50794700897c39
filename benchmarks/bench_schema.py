"""The ``[network]`` table checked three ways: the project's readers (tomlcheck), pydantic 2
and msgspec, with the same keys and cross-key rules, to decide whether a schema library
should replace our checker (the decision is in docs/concepts/layout.md).

    pip install pydantic msgspec   # neither is a dependency of the project
    python benchmarks/bench_schema.py

Prints, for each, the time to check a valid table (min / median of 5 × 2000) and what it
says of a table with four mistakes.
"""

import statistics
import sys
import time
from typing import Annotated, Literal

try:
    import msgspec
    import pydantic
    from pydantic import BaseModel, ConfigDict, Field, model_validator
except ImportError as exc:
    sys.exit(f"bench_schema.py compares with pydantic and msgspec: pip install them ({exc})")

from dftc_mujoco.errors import ScenarioError
from dftc_mujoco.runtime.tomlcheck import Doc, Table
from dftc_mujoco.scenario.network import read_network
from dftc_mujoco.scenario.parts import Physics

GOOD = {
    "latency": {"mean": 0.05, "max": 0.1},
    "rate": 50.0,
    "loss": 0.1,
    "loss_model": "gilbert_elliott",
    "p_bad": 0.1,
    "p_good": 0.5,
    "max_consecutive_losses": 5,
    "range": 2.0,
    "range_hysteresis": 0.2,
    "links": [{"link": [4, 2], "loss": 0.2, "latency": 0.08}],
}
BAD = {
    **GOOD,
    "latency": {"mean": 0.05, "max": 0.01},
    "loss": "high",
    "range_hysteresis": 3.0,
    "rnage": 1,
}
H = 0.01


def ours(data):
    doc = Doc("s.toml", {"network": data})
    t = Table("s.toml", data, "network", doc)
    read_network(t, Physics(), ())
    doc.raise_problems()


class Latency(BaseModel):
    model_config = ConfigDict(extra="forbid")
    mean: Annotated[float, Field(gt=0)]
    max: Annotated[float, Field(gt=0)]

    @model_validator(mode="after")
    def _order(self):
        if self.max < self.mean:
            raise ValueError(f"expected at least mean = {self.mean:g} s, got {self.max:g}")
        return self


class Link(BaseModel):
    model_config = ConfigDict(extra="forbid")
    link: tuple[int, int]
    loss: Annotated[float, Field(ge=0, le=1)] | None = None
    latency: Annotated[float, Field(ge=0)] | None = None


class NetP(BaseModel):
    model_config = ConfigDict(extra="forbid")
    latency: Latency | Annotated[float, Field(ge=0)] = 0.0
    rate: Annotated[float, Field(gt=0)] | None = None
    loss: Annotated[float, Field(ge=0, le=1)] = 0.0
    loss_model: Literal["bernoulli", "gilbert_elliott"] = "bernoulli"
    p_bad: Annotated[float, Field(ge=0, le=1)] = 0.0
    p_good: Annotated[float, Field(ge=0, le=1)] = 1.0
    loss_bad: Annotated[float, Field(ge=0, le=1)] = 1.0
    max_consecutive_losses: Annotated[int, Field(ge=0)] | None = None
    range: Annotated[float, Field(gt=0)] | None = None
    range_hysteresis: Annotated[float, Field(ge=0)] = 0.0
    links: list[Link] = []

    @model_validator(mode="after")
    def _cross(self):
        if self.rate is not None and self.rate * H > 1 + 1e-9:
            raise ValueError("rate: a robot sends at most once a control period")
        if self.range is not None and self.range_hysteresis >= self.range:
            raise ValueError(
                f"range_hysteresis: expected less than range = {self.range:g} m, "
                f"got {self.range_hysteresis:g}"
            )
        return self


def pyd(data):
    NetP.model_validate(data)


class LatencyM(msgspec.Struct, forbid_unknown_fields=True):
    mean: Annotated[float, msgspec.Meta(gt=0)]
    max: Annotated[float, msgspec.Meta(gt=0)]


class LinkM(msgspec.Struct, forbid_unknown_fields=True):
    link: tuple[int, int]
    loss: Annotated[float, msgspec.Meta(ge=0, le=1)] | None = None
    latency: Annotated[float, msgspec.Meta(ge=0)] | None = None


class NetM(msgspec.Struct, forbid_unknown_fields=True):
    latency: LatencyM | Annotated[float, msgspec.Meta(ge=0)] = 0.0
    rate: Annotated[float, msgspec.Meta(gt=0)] | None = None
    loss: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.0
    loss_model: Literal["bernoulli", "gilbert_elliott"] = "bernoulli"
    p_bad: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.0
    p_good: Annotated[float, msgspec.Meta(ge=0, le=1)] = 1.0
    loss_bad: Annotated[float, msgspec.Meta(ge=0, le=1)] = 1.0
    max_consecutive_losses: Annotated[int, msgspec.Meta(ge=0)] | None = None
    range: Annotated[float, msgspec.Meta(gt=0)] | None = None
    range_hysteresis: Annotated[float, msgspec.Meta(ge=0)] = 0.0
    links: list[LinkM] = []

    def __post_init__(self):
        if self.rate is not None and self.rate * H > 1 + 1e-9:
            raise ValueError("rate: a robot sends at most once a control period")
        if isinstance(self.latency, LatencyM) and self.latency.max < self.latency.mean:
            raise ValueError("latency.max: expected at least mean")
        if self.range is not None and self.range_hysteresis >= self.range:
            raise ValueError("range_hysteresis: expected less than range")


def msg(data):
    msgspec.convert(data, NetM)


def bench(f, data, n=2000):
    best = []
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(n):
            f(data)
        best.append((time.perf_counter() - t0) / n * 1e6)
    return min(best), statistics.median(best)


for name, f in (("tomlcheck (ours)", ours), ("pydantic 2", pyd), ("msgspec", msg)):
    lo, med = bench(f, GOOD)
    try:
        f(BAD)
        out = "(accepted!)"
    except (ScenarioError, pydantic.ValidationError, msgspec.ValidationError, ValueError) as e:
        out = str(e)
    print(f"## {name}: {lo:.1f} / {med:.1f} µs per valid table (min / median of 5 x 2000)\n{out}\n")
