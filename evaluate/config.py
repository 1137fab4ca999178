"""The [evaluate] section: bootstrap settings, the alarm-policy grid swept on validation flights and
the rule's target false-alarm rate (docs/evaluation.md). Every policy of the grid is checked as an
[alarm] policy (core.alarm, the contract the C++ mirrors)."""

from __future__ import annotations

from dataclasses import dataclass

from quadfdi.core.alarm import AlarmConfig
from quadfdi.core.errors import QuadfdiError


def parse_kn(text: str) -> tuple[int, int]:
    """'k/n' -> (k, n), one-line error otherwise."""
    k, sep, n = str(text).partition("/")
    if not sep or not k.strip().isdigit() or not n.strip().isdigit():
        raise QuadfdiError(f"evaluate.kn entries must be 'k/n' such as '2/3', found {text!r}")
    return int(k), int(n)


@dataclass(frozen=True)
class EvaluateConfig:
    """How ``quadfdi evaluate`` measures (docs/evaluation.md)."""

    bootstrap: int = 2000  # flight-resampling replicates of every interval (>= 1000)
    seed: int = 0  # of the resampling
    ci: float = 0.95  # interval coverage (percentile bootstrap, Garwood Poisson)
    thresholds: tuple[float, ...] = (0.5, 0.7, 0.9, 0.97, 0.99)  # alarm grid: p_fault threshold ...
    kn: tuple[str, ...] = ("1/1", "2/3", "3/5", "5/8", "8/12")  # ... x k of n windows (0.8 s apart in the suite) ...
    clear_m: tuple[int, ...] = (3, 8)  # ... x consecutive non-voting windows to clear
    target_fa_per_h: float = 1.0  # the policy rule: validation false alarms per flight-hour at most this
    # model-name prefixes of the networks (others: baselines)
    networks: tuple[str, ...] = ("cnode", "gru", "sgru", "scnode")

    def validate(self) -> None:
        if self.bootstrap < 1000:
            raise QuadfdiError(f"evaluate.bootstrap must be at least 1000 replicates, found {self.bootstrap}")
        if self.seed < 0:
            raise QuadfdiError(f"evaluate.seed must not be negative, found {self.seed}")
        if not 0.5 < self.ci < 1.0:
            raise QuadfdiError(f"evaluate.ci must be in (0.5, 1), found {self.ci}")
        if not self.thresholds or not self.kn or not self.clear_m:
            raise QuadfdiError("evaluate.thresholds, evaluate.kn and evaluate.clear_m need at least one value each")
        for t in self.thresholds:
            for kn in self.kn:
                for m in self.clear_m:
                    k, n = parse_kn(kn)
                    try:
                        AlarmConfig(threshold=t, k=k, n=n, clear_m=m).validate()
                    except QuadfdiError as exc:
                        raise QuadfdiError(f"evaluate grid (threshold {t}, kn {kn}, clear_m {m}): {exc}") from None
        if not self.target_fa_per_h > 0:
            raise QuadfdiError(f"evaluate.target_fa_per_h must be positive, found {self.target_fa_per_h}")
