"""Community benchmarks reproduced (docs/benchmark.md)."""

from __future__ import annotations

import os
from typing import Any, Dict, Optional

from . import _substep

__all__ = ["rths"]


def rths(
    *,
    case: Optional[int] = None,
    intensity: float = 0.4,
    controller: Optional[str] = None,
    config: Optional["os.PathLike[str] | str"] = None,
    algorithm: str = "benchmark",
) -> Dict[str, Any]:
    """The virtual RTHS benchmark (Silva et al. 2020) with the nominal servo-hydraulic plant.

    ``case``: reference structure 1..4 (default: all four); ``intensity``: scale of the El Centro
    record; ``controller``: none, sample, arx, polynomial, inverse_fir (default: the config's,
    else sample); ``config``: a benchmark settings file (TOML, docs/benchmark.md);
    ``algorithm``: ``benchmark`` (the original loop) or ``substep``.

    Returns the dict of ``substep benchmark rths --json`` for those options: ``controller``,
    ``record``, ``intensity``, ``algorithm`` and ``cases``, one dict per case with ``J1`` ... ``J9``
    (None if it diverged), ``max_force``, ``stable``, ``capacity_exceeded``.
    """
    cfg = None if config is None else os.fspath(config)
    return _substep.rths(case, float(intensity), controller, cfg, algorithm)
