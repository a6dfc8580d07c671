"""Accuracy and stability analysis of the sub-step algorithm (docs/analysis.md, theory.md §9).

The numbers are the library's, as ``substep analyze stability|accuracy|verify`` computes them; the
defaults are the CLI's. Each function returns a dict of numpy arrays named like the columns of
the CSV file the CLI writes (``stability.csv``, ``accuracy.csv``).
"""

from __future__ import annotations

from typing import Dict, Optional, Sequence, Tuple

import numpy as np

from . import _substep

Grid = Tuple[float, float, int]

__all__ = ["stability", "accuracy", "transfer_function", "plan", "verify"]


def _grid(what: str, g) -> Grid:
    if isinstance(g, str):
        parts = g.split(":")
        if len(parts) != 3:
            raise _substep.ConfigError(f"{what}: expected a grid a:b:n, got '{g}'")
        return float(parts[0]), float(parts[1]), int(parts[2])
    a, b, n = g
    return float(a), float(b), int(n)


def _vary(v) -> Tuple[str, Grid]:
    if isinstance(v, str):
        name, _, grid = v.partition("=")
        if not grid:
            raise _substep.ConfigError(f"vary: expected name=a:b:n, got '{v}'")
        return name.strip(), _grid("vary", grid)
    name, grid = v
    return str(name), _grid("vary", grid)


def _arrays(d: Dict[str, list]) -> Dict[str, np.ndarray]:
    return {k: np.asarray(v) for k, v in d.items()}


def stability(
    *,
    case: str = "typical",
    eta_m: Optional[float] = None,
    eta_f: Optional[float] = None,
    zeta: Optional[float] = None,
    zeta_s: Optional[float] = None,
    error_force: str = "none",
    eta_p: float = 0.0,
    phase_lag: str = "none",
    k_sub: Sequence[int] = (1, 2, 3, 4, 5),
    omega="0.015708:3.141593:200",
    vary="zeta_s=0:0.5:200",
) -> Dict[str, np.ndarray]:
    """Spectral radius ρ of the sub-step algorithm over a grid of Ω = ωΔt and one parameter.

    ``case``: ``typical`` (η_m 5 %, ζ 5 %, ζ_s 10 %, η_f 1) or ``large_mass_ratio``, with the
    overrides ``eta_m``, ``eta_f``, ``zeta``, ``zeta_s``; ``error_force``: ``none``, ``pid:P`` or
    ``pid:P:I:D``; ``eta_p``: phase-lag ratio τ/Δt; ``phase_lag``: ``none``,
    ``polynomial:ORDER`` or ``arx`` (frozen at its converged parameters); ``k_sub``: a list; ``omega``: a grid ``(a, b, n)`` or ``"a:b:n"``;
    ``vary``: ``(name, (a, b, n))`` or ``"name=a:b:n"`` with name one of zeta_s, zeta, eta_f,
    eta_m, eta_p.

    Returns the columns of ``stability.csv``: ``k_sub``, ``Omega``, the varied parameter's name,
    ``rho`` (one entry per grid point). Bad parameters raise ``substep.ConfigError``.
    """
    name, grid = _vary(vary)
    return _arrays(
        _substep.stability(case, eta_m, eta_f, zeta, zeta_s, error_force, float(eta_p), phase_lag,
                           [int(k) for k in k_sub], _grid("omega", omega), name, grid)
    )


def accuracy(
    *,
    case: str = "typical",
    eta_m: Optional[float] = None,
    eta_f: Optional[float] = None,
    zeta: Optional[float] = None,
    zeta_s: Optional[float] = None,
    error_force: str = "none",
    eta_p: Sequence[float] = (0.0,),
    k_sub: Sequence[int] = (1, 2, 5),
    eta_t: Sequence[float] = (0.005, 0.01, 0.02, 0.03, 0.05, 0.075, 0.1, 0.125, 0.15, 0.2),
    vary=None,
) -> Dict[str, np.ndarray]:
    """Peaks of the transfer function: amplitude and period errors against the exact system.

    Parameters as for :func:`stability`; ``eta_p``, ``k_sub`` and ``eta_t`` (η_T = Δt/T) are lists,
    ``vary`` an optional series ``(name, (a, b, n))``.

    Returns the columns of ``accuracy.csv``: ``k_sub``, ``eta_T``, ``eta_p``, (the varied
    parameter), ``peak``, ``freq_ratio``, ``h``, ``freq_ratio_exact``, ``h_exact``,
    ``amplitude_error``, ``period_error`` (one entry per peak).
    """
    name, grid = _vary(vary) if vary is not None else (None, None)
    return _arrays(
        _substep.accuracy(case, eta_m, eta_f, zeta, zeta_s, error_force, [float(x) for x in eta_p],
                          [int(k) for k in k_sub], [float(x) for x in eta_t], name, grid)
    )


def transfer_function(
    *,
    case: str = "typical",
    eta_m: Optional[float] = None,
    eta_f: Optional[float] = None,
    zeta: Optional[float] = None,
    zeta_s: Optional[float] = None,
    error_force: str = "none",
    eta_p: float = 0.0,
    k_sub: int = 1,
    eta_t: float = 0.05,
    r: Optional[Sequence[float]] = None,
) -> Dict[str, np.ndarray]:
    """Dynamic amplification ``h = |u₁| ω²/|a_g|`` of the primary DOF against the frequency ratio
    ``r = ω_exc/ω``: the sub-step algorithm's (``h``) and the exact system's (``h_exact``), as the
    CLI's ``transfer_function_k*.png`` draws them (default grid: r = 0.5 … 1.5, 601 points).
    Case parameters as for :func:`stability`.
    """
    grid = np.linspace(0.5, 1.5, 601) if r is None else np.asarray(r, dtype=float)
    return _arrays(
        _substep.transfer_function(case, eta_m, eta_f, zeta, zeta_s, error_force, float(eta_p), int(k_sub),
                                   float(eta_t), [float(x) for x in grid])
    )


def plan(
    config,
    *,
    dt: Optional[Sequence[float]] = None,
    k_sub: Optional[Sequence[int]] = None,
    delay: Optional[Sequence[float]] = None,
    tolerance: float = 0.02,
    margin: float = 1e-3,
    budget: float = 0.5,
) -> Dict[str, object]:
    """Which Δt / k_sub / delay for this test? ``substep analyze plan`` for a test definition
    (a path, TOML text or dict with a ``[substructure]`` of linear specimens).

    ``dt`` (default: the config's Δt × 2, 1, 1/2), ``k_sub`` (default: 1, 2, 4, 8 and the
    config's), ``delay`` (default: the config's); ``tolerance``: accepted peak error;
    ``margin``: required 1 − ρ; ``budget``: share of Δt the computation may take.

    Returns the columns of ``plan.csv`` as arrays (one row per peak of each scanned setting;
    ``us_per_step`` and ``budget_share`` are measured on this machine), ``recommended`` (a dict
    ``dt, k_sub, delay`` or None) and ``phase_lag_note``.
    """
    from . import _config_source
    import os

    kind, text, name = _config_source(config)
    out = _substep.plan(kind, text, name, os.getcwd(),
                        None if dt is None else [float(x) for x in dt],
                        None if k_sub is None else [int(k) for k in k_sub],
                        None if delay is None else [float(x) for x in delay],
                        float(tolerance), float(margin), float(budget))
    return {k: (np.asarray(v) if isinstance(v, list) else v) for k, v in out.items()}


def verify() -> Dict[str, object]:
    """Check the frequency-domain analysis in the time domain (``substep analyze verify``,
    docs/theory.md §9.6): stepped-sine sweeps against the discrete frequency response's peaks,
    free-vibration runs inside, on and outside the stability boundary against the spectral
    radius, and a PID compensation moving an unstable point into the stable region.

    Returns the columns of ``verify.csv`` (one entry per check: ``check, case, k_sub, Omega,
    eta_p, quantity, frequency_domain, time_domain, agrees``, each an array) and
    ``all_agree``. Takes about half a second.
    """
    out = _substep.verify()
    return {k: (v if k == "all_agree" else np.asarray(v)) for k, v in out.items()}
