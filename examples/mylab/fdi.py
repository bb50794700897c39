"""A threshold rule of one's own: the paper's eq. 40 scaled by a factor."""

from dftc_mujoco.blocks import paper


class Scaled(paper.Thresholds):
    """ⁱμ_k(t) = factor × eq. 40. With factor < 1 faults are flagged earlier, at the risk of
    false alarms (eq. 40 is a bound; a scaled one is not)."""

    def __init__(self, factor: float = 0.5) -> None:
        if not factor > 0:
            raise ValueError(f"factor must be > 0, got {factor}")
        self.factor = float(factor)

    def mu(self, t):
        return self.factor * super().mu(t)
