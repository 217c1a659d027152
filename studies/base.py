"""What every study declares: parameters with validation, a run, and a plot that reads results."""

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from araim.validate import check_int, check_positive, check_probability, check_range


@dataclass(frozen=True)
class Param:
    """One ``--set KEY=VALUE`` parameter: its default, a parser that validates, and its meaning."""

    default: Any
    parse: Callable[[str, Any], Any]  # (name, raw value) -> value, raises ValueError naming name
    doc: str
    unit: str = ""


def probability(name, v):
    return check_probability(name, v)


def positive(name, v):
    return check_positive(name, v)


def non_negative(name, v):
    return check_positive(name, v, allow_zero=True)


def count(minimum, maximum=None):
    return lambda name, v: check_int(name, v, minimum, maximum)


def in_range(lo, hi):
    return lambda name, v: check_range(name, v, lo, hi)


@dataclass
class StudyResult:
    dataset: Any  # xarray.Dataset
    rows: list  # [{"quantity", "unit", "published", "reproduced", "note"}]
    metrics: dict
    extra_provenance: dict = field(default_factory=dict)


class Study:
    """Base class. Subclasses set the class attributes and implement ``run`` and ``plot``."""

    name: str = ""
    title: str = ""
    seed_file: str = ""
    realization: str = ""  # what one realization is
    default_realizations: int = 1
    quick_realizations: int = 1
    params: dict = {}

    def validate(self, overrides: dict) -> dict:
        """Defaults updated with ``overrides`` (raw strings or values), each parsed and checked."""
        unknown = sorted(set(overrides) - set(self.params))
        if unknown:
            raise ValueError(
                f"unknown parameter {unknown[0]!r} for study {self.name}; valid keys: "
                + ", ".join(sorted(self.params)))
        out = {}
        for key, p in self.params.items():
            out[key] = p.parse(key, overrides.get(key, p.default))
        self.check(out)
        return out

    def check(self, params: dict) -> None:
        """Cross-parameter checks (e.g. d_min < d_max); raise ValueError naming the fields."""

    def run(self, params: dict, realizations: int, seed: int, progress) -> StudyResult:
        raise NotImplementedError

    def plot(self, out_dir) -> list:
        raise NotImplementedError

