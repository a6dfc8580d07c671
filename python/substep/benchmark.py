"""Community benchmarks reproduced (docs/benchmark.md)."""

from __future__ import annotations

import json
import os
from typing import Any, Dict, Optional, Sequence

from . import _substep

__all__ = ["rths", "compare", "marths"]


def _count(what: str, x, top: int = 2**63 - 1) -> int:
    """A whole number >= 0 (the range checks after it are the library's, with its message)."""
    if isinstance(x, bool) or int(x) != x or not 0 <= int(x) <= top:
        raise _substep.ConfigError(f"{what}: must be a whole number in 0..={top}, got {x!r}")
    return int(x)


def rths(
    *,
    case: Optional[int] = None,
    intensity: float = 0.4,
    controller: Optional[str] = None,
    config: Optional["os.PathLike[str] | str"] = None,
    algorithm: str = "benchmark",
    record: Optional["os.PathLike[str] | str"] = None,
    perturbed: Optional[int] = None,
    seed: int = 1,
    k_sub: Optional[Sequence[int]] = None,
) -> Dict[str, Any]:
    """The virtual RTHS benchmark (Silva et al. 2020): the servo-hydraulic plant with
    control-structure interaction, J1-J9 against the exact reference.

    ``case``: reference structure 1..4 (default: all four); ``intensity``: scale of the record;
    ``controller``: none, sample, arx, polynomial, ats, amb (default: the config's, else
    sample); ``config``: a benchmark settings file (TOML, docs/benchmark.md); ``algorithm``:
    ``benchmark`` (the original loop) or ``substep``; ``record``: a two-column ``t,a_g`` CSV in
    m/s² (default: the shipped El Centro record); ``perturbed``: also run that many perturbed
    plants per case (seed ``seed``), the benchmark's robustness study; ``k_sub``: with
    ``algorithm="substep"``, one row per value.

    Returns the dict of ``substep benchmark rths --json`` for the same options: ``controller``,
    ``record``, ``intensity``, ``algorithm`` (``dt``, ``error_force`` with substep, ``seed`` with
    perturbed plants) and ``cases``, one dict per case (and ``k_sub``) with ``J1`` ... ``J9``
    (None if it diverged), ``max_force``, ``stable``, ``capacity_exceeded`` and, with perturbed
    plants, ``perturbed``: ``n``, ``stable``, ``under_capacity``, ``mean`` and ``max`` of each J
    over the stable runs, ``max_force`` and every run's plant (``k_e``, ``beta1``, ``beta2``,
    ``a3``) and J values. With a single row its fields are at the top level too.
    """
    cfg = None if config is None else os.fspath(config)
    rec = None if record is None else os.fspath(record)
    if rec == "elcentro":
        rec = None
    ks = [] if k_sub is None else [_count("k_sub", k) for k in k_sub]
    n = None if perturbed is None else _count("perturbed", perturbed)
    c = None if case is None else _count("case", case, 255)
    text = _substep.rths(c, float(intensity), controller, cfg, algorithm, rec, n, _count("seed", seed, 2**64 - 1), ks)
    return json.loads(text)


def compare(
    *,
    case: Optional[int] = None,
    intensity: float = 0.4,
    record: Optional["os.PathLike[str] | str"] = None,
    perturbed: int = 20,
    seed: int = 1,
) -> Dict[str, Any]:
    """The controllers side by side on the RTHS benchmark (``substep benchmark rths --compare``,
    docs/benchmark.md "Comparison"): none, sample, polynomial, ats, amb and arx, each with its one
    preset setting, with and without sensor noise, on the nominal plant and ``perturbed`` plants
    per case (seed ``seed``; 0: none).

    Returns the dict of ``substep benchmark rths --compare --json``: ``record``, ``intensity``,
    ``perturbed``, ``seed`` and ``comparison``, one dict per controller, noise setting and case
    with ``J2``, ``J4`` [%] and ``max_force`` [N] of the nominal plant (None if it diverged),
    ``stable``, ``perturbed_stable``, ``under_capacity``, the worst ``J2``/``J4``/force over the
    stable perturbed runs and ``cpu_us_per_sample`` (the controller alone, replayed on the nominal
    run's signals). ``pandas.DataFrame(result["comparison"])`` makes it a table.
    """
    rec = None if record is None else os.fspath(record)
    if rec == "elcentro":
        rec = None
    c = None if case is None else _count("case", case, 255)
    text = _substep.rths_compare(c, float(intensity), rec, _count("perturbed", perturbed), _count("seed", seed, 2**64 - 1))
    return json.loads(text)


def marths(
    *,
    record: "os.PathLike[str] | str" = "elcentro",
    intensity: float = 0.4,
    controller: str = "rodeac",
    trials: int = 0,
    seed: int = 123,
    noise: bool = True,
    ideal: bool = False,
    algorithm: str = "benchmark",
    partition_density: Optional[float] = None,
    config: Optional["os.PathLike[str] | str"] = None,
) -> Dict[str, Any]:
    """The multi-axial RTHS benchmark (Condori Uribe et al. 2023; ``substep benchmark marths``,
    docs/benchmark.md "maRTHS"): two actuators on a coupler drive x and θ of a frame node.

    ``record``: elcentro, kobe, morgan (shipped) or a two-column ``t,a_g`` CSV in m/s²;
    ``intensity``: scale of the record; ``controller``: none, rodeac, arx or arx_mimo;
    ``trials``: uncertain plants (0: the nominal plant's J, else the mean over the trials, as the
    toolset reports); ``seed``: of the plants and the sensor noise; ``noise``: sensor noise on;
    ``ideal``: an ideal transfer system (measured = target); ``algorithm``: ``benchmark`` or
    ``substep``; ``partition_density``: kg/m³ (the toolset's 785e3 by default); ``config``: a
    settings file (TOML: ``[plant]``, ``[coupler]``, ``[controller.arx]``, ``[substep]``).

    Returns the dict of ``substep benchmark marths --json``: ``J1`` ... ``J10`` (lists in the
    toolset's order, rounded to 0.1), ``J_raw`` (unrounded), ``nominal``, ``per_trial``,
    ``realizable``, ``peak_volts``, ``stable``. Raises ``ConfigError`` on bad input and
    ``RunError`` when a run diverged.
    """
    text = _substep.marths(
        os.fspath(record),
        float(intensity),
        controller,
        _count("trials", trials),
        _count("seed", seed, 2**64 - 1),
        bool(noise),
        bool(ideal),
        algorithm,
        None if partition_density is None else float(partition_density),
        None if config is None else os.fspath(config),
    )
    return json.loads(text)
