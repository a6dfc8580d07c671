"""Parameter studies: every variant of a base test, one DataFrame row per run.

>>> import substep
>>> df = substep.study("examples/studies/tmd_base.toml",
...                    grid={"substructure.substeps": [1, 2, 4, 8],
...                          "substructure.actuator.delay": [0.005, 0.01]},
...                    metrics=["max_displacement_error", "tracking_delay"])   # doctest: +SKIP

The runs are the Rust library's (``substep::study``): locally on all cores (rayon, GIL
released); with ``client=`` (a ``dask.distributed.Client``) in batches of runs, one task per
batch. Run ``i`` is defined by its index alone (grid point, sample drawn from the study seed on
stream ``i``, noise seed), so the DataFrame is the same either way.
"""

from __future__ import annotations

import json
import os
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Union

from . import _substep

__all__ = ["study", "StudyPlan"]

MetricLike = Union[str, Callable[[Dict[str, Any]], Any]]


def _distribution(key: str, spec: Any) -> Dict[str, Any]:
    """A distribution as the library reads it: a dict (``{"dist": "uniform", "low": .., "high": ..}``)
    or a tuple ``("uniform", low, high)``, ``("normal", mean, std)``, ``("log_uniform", low, high)``,
    with an optional last element ``"relative"`` (the sample multiplies the base value)."""
    if isinstance(spec, Mapping):
        return dict(spec)
    if isinstance(spec, (tuple, list)) and len(spec) in (3, 4) and isinstance(spec[0], str):
        dist, a, b = spec[0], spec[1], spec[2]
        relative = len(spec) == 4 and spec[3] == "relative"
        if len(spec) == 4 and not relative:
            raise ValueError(f"samples[{key!r}]: the 4th element may only be 'relative', got {spec[3]!r}")
        names = ("mean", "std") if dist == "normal" else ("low", "high")
        return {"dist": dist, names[0]: a, names[1]: b, "relative": relative}
    raise ValueError(f"samples[{key!r}]: give a dict or (dist, a, b[, 'relative']), got {spec!r}")


def _spec(grid, samples, seeds, seed_key, metrics: List[str]) -> str:
    spec: Dict[str, Any] = {}
    if grid:
        spec["grid"] = {k: list(v) if isinstance(v, (list, tuple, range)) else [v] for k, v in grid.items()}
    if samples:
        s = dict(samples)
        n = s.pop("n", None)
        seed = s.pop("seed", 0)
        params = s.pop("params", None)
        if params is None:
            params, s = s, {}
        if s:
            raise ValueError(f"samples: unknown keys {sorted(s)} (n, seed, params or parameter keys)")
        if n is None:
            raise ValueError("samples: give n, the number of random samples")
        spec["samples"] = {"n": int(n), "seed": int(seed),
                           "params": {k: _distribution(k, v) for k, v in params.items()}}
    if seeds is not None:
        spec["seeds"] = [int(s) for s in seeds]
    if seed_key is not None:
        spec["seed_key"] = seed_key
    if metrics:
        spec["metrics"] = metrics
    return json.dumps(spec, allow_nan=True)


class StudyPlan:
    """A validated study: ``len(plan)`` runs, ``parameters`` (the varied keys, column order) and
    ``metrics`` (the library metrics' names)."""

    def __init__(self, base, grid=None, samples=None, seeds=None, metrics=None, seed_key=None) -> None:
        from . import _config_source

        kind, text, name = _config_source(base)
        if kind == "path":
            text = name = os.path.abspath(text)  # Dask workers may run elsewhere
        self.source = (kind, text, name, os.getcwd())
        metrics = list(metrics) if metrics is not None else []
        self.functions: List[Callable[[Dict[str, Any]], Any]] = [m for m in metrics if callable(m)]
        named = [m for m in metrics if not callable(m)]
        for m in named:
            if not isinstance(m, str):
                raise TypeError(f"metrics: give names or functions of the summary, not {type(m).__name__}")
        if metrics and not named:
            named = ["steps_done"]  # a study needs one library metric; user functions add the rest
        self.spec = _spec(grid, samples, seeds, seed_key, named)
        n, self.parameters, self.metrics = _substep.study_plan(*self.source, self.spec)
        self.n = n

    def __len__(self) -> int:
        return self.n

    def run_batch(self, indices: Optional[Sequence[int]], threads: int = 0) -> List[Dict[str, Any]]:
        """Records (dicts: run, the parameters, completed, the metrics, error) of the runs
        ``indices`` (all when None), with the user functions applied to each summary."""
        rows = _substep.study_run(*self.source, self.spec, None if indices is None else list(indices),
                                  threads, bool(self.functions))
        records = []
        for r in rows:
            rec: Dict[str, Any] = {"run": r["run"]}
            rec.update(zip(self.parameters, r["values"]))
            rec["completed"] = r["completed"]
            rec.update(zip(self.metrics, r["metrics"]))
            rec["error"] = r["error"]
            if self.functions:
                summary = json.loads(r["summary"]) if r.get("summary") else None
                for f in self.functions:
                    rec.update(_apply(f, summary, rec))
                rec["error"] = rec.pop("error")  # the last column
            records.append(rec)
        return records


def _apply(f: Callable[[Dict[str, Any]], Any], summary, rec) -> Dict[str, Any]:
    """A user metric: ``f(summary)`` → a number (column ``f.__name__``) or a dict of columns.
    A run without a summary, or an exception in ``f``, gives NaN (and the reason in ``error``)."""
    name = getattr(f, "__name__", "metric")
    if summary is None:
        return {name: float("nan")}
    try:
        value = f(summary)
    except Exception as e:  # the user's function: its failure must not lose the other rows
        prefix = rec.get("error") or ""
        rec["error"] = (prefix + "; " if prefix else "") + f"metric {name}: {type(e).__name__}: {e}"
        return {name: float("nan")}
    return dict(value) if isinstance(value, Mapping) else {name: value}


def _run_batch(plan: StudyPlan, indices: List[int]) -> List[Dict[str, Any]]:
    # One Dask task: one thread, so that tasks on a worker do not oversubscribe its cores.
    return plan.run_batch(indices, threads=1)


def study(base, grid: Optional[Mapping[str, Sequence[Any]]] = None, samples: Optional[Mapping[str, Any]] = None,
          seeds: Optional[Sequence[int]] = None, metrics: Optional[Sequence[MetricLike]] = None,
          client=None, *, seed_key: Optional[str] = None, threads: int = 0,
          batch_size: Optional[int] = None):
    """Run every variant of ``base`` and return a ``pandas.DataFrame``, one row per run.

    * ``base``: the test definition (path, TOML text or dict, as for :func:`substep.run`).
    * ``grid``: ``{dotted key: [values]}``, the cartesian product (keys in name order, the first
      varies slowest), e.g. ``{"substructure.substeps": [1, 2, 4, 8]}``.
    * ``samples``: ``{"n": N, "seed": S, "params": {key: dist}}`` (or the keys directly beside
      ``n`` and ``seed``): N seeded random samples per grid point; ``dist`` is
      ``("uniform", low, high)``, ``("normal", mean, std)``, ``("log_uniform", low, high)``,
      with ``"relative"`` as 4th element to scale the base value (``("uniform", 0.9, 1.1,
      "relative")`` is ±10 %), or the dict form of docs/config.md.
    * ``seeds``: noise seeds, each variant once per seed (key ``seed_key``, by default
      ``substructure.sensors.seed``).
    * ``metrics``: library metric names (docs/config.md "Study files": ``max_displacement_error``,
      ``tracking_delay``, ... or a dotted path into summary.json) and functions ``f(summary) ->
      number | dict`` that add columns.
    * ``client``: a ``dask.distributed.Client``: the runs go to its cluster in batches of
      ``batch_size`` (default: about 4 batches per worker); the rows equal the local ones.
    * ``threads``: local threads (0: all cores).

    Columns: ``run``, the varied keys, ``completed``, the metrics, ``error`` (why a run did not
    complete: the run, its overrides and the config's message). A failing run does not stop
    the others.
    """
    import pandas as pd

    plan = StudyPlan(base, grid, samples, seeds, metrics, seed_key)
    if client is None:
        records = plan.run_batch(None, threads)
    else:
        n = len(plan)
        if batch_size is None:
            workers = max(1, len(client.scheduler_info().get("workers", {})))
            batch_size = max(1, -(-n // (4 * workers)))
        batches = [list(range(i, min(i + batch_size, n))) for i in range(0, n, batch_size)]
        futures = client.map(_run_batch, [plan] * len(batches), batches, pure=False)
        records = [rec for batch in client.gather(futures) for rec in batch]
    frame = pd.DataFrame.from_records(records)
    return frame.set_index("run", drop=False).rename_axis(None)
