"""substep: real-time substructure testing (hybrid simulation) with Dorka's sub-step control.

A thin Python front end over the Rust library ``substep`` (no numerics in Python): the run
loop, the reference solution, the summary and the analyses are the library's, so the numbers
are the ones the ``substep`` command line writes.

>>> import substep
>>> r = substep.run("examples/default.toml")
>>> r.summary["reference"]["max_displacement_error"]     # doctest: +SKIP
0.01714...
>>> r.to_pandas().head()                                  # doctest: +SKIP

See ``docs/python.md`` for a worked example.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Tuple, Union

import numpy as np

from . import _substep
from ._substep import ConfigError, RunError

__all__ = ["run", "Result", "Table", "ConfigError", "RunError", "analyze", "benchmark", "study"]

ConfigLike = Union[str, "os.PathLike[str]", Mapping[str, Any]]


class Table:
    """Named columns of a run, as one ``rows × columns`` float64 array.

    ``names`` are the CSV's column names, ``values`` the array; ``table["u1"]`` is one column.
    """

    def __init__(self, names: List[str], values: np.ndarray) -> None:
        self.names = list(names)
        self.values = values

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.values[:, self.names.index(name)]
        except ValueError:
            raise KeyError(f"no column {name!r} (columns: {', '.join(self.names)})") from None

    def __len__(self) -> int:
        return self.values.shape[0]

    def group(self, prefix: str) -> np.ndarray:
        """The columns ``prefix1, prefix2, ...`` as a ``rows × count`` array (e.g. ``"u"``)."""
        cols = [k for k, n in enumerate(self.names) if n.startswith(prefix) and n[len(prefix):].isdigit()]
        return self.values[:, cols]

    def to_pandas(self):
        """A ``pandas.DataFrame`` with the CSV's column names."""
        import pandas as pd

        return pd.DataFrame(self.values, columns=self.names)

    def __repr__(self) -> str:
        return f"Table({len(self)} rows: {', '.join(self.names)})"


def _table(pair) -> Optional[Table]:
    if pair is None:
        return None
    names, columns = pair
    # The library hands columns × rows; the transpose is a view (no copy).
    return Table(names, np.asarray(columns).T)


_FIGURE_SUFFIXES = (".png", ".svg", ".pdf")
_MIME = {".png": "image/png", ".svg": "image/svg+xml", ".pdf": "application/pdf"}


class Figure:
    """One figure of a run (``displacement``, ``hysteresis``, ``reference``, ...): the bytes of
    the PNG, SVG or PDF file ``substep run`` draws, shown inline by Jupyter."""

    def __init__(self, name: str, suffix: str, data: bytes) -> None:
        self.name, self.format, self.data = name, suffix.lstrip("."), data

    def save(self, path: Union[str, "os.PathLike[str]"]) -> str:
        """Write the figure's file to ``path``; returns it."""
        Path(path).write_bytes(self.data)
        return os.fspath(path)

    def _repr_png_(self) -> Optional[bytes]:
        return self.data if self.format == "png" else None

    def _repr_svg_(self) -> Optional[str]:
        return self.data.decode() if self.format == "svg" else None

    def _repr_html_(self) -> str:
        if self.format == "pdf":
            return f"<p>{self.name}.pdf ({len(self.data)} bytes; save() it, or plot(format='png') to see it)</p>"
        import base64

        b64 = base64.b64encode(self.data).decode()
        return f'<figure><img src="data:{_MIME["." + self.format]};base64,{b64}" alt="{self.name}" style="max-width:100%"/>' \
               f"<figcaption>{self.name}</figcaption></figure>"

    def __repr__(self) -> str:
        return f"<substep.Figure {self.name}.{self.format}, {len(self.data)} bytes>"


class Figures(list):
    """The figures of a run in the order ``substep run`` draws them; ``figures["hysteresis"]``
    picks one by name. Jupyter shows them all."""

    def __getitem__(self, key):
        if isinstance(key, str):
            for f in self:
                if f.name == key:
                    return f
            raise KeyError(f"{key!r}: no such figure (this run drew {', '.join(f.name for f in self) or 'none'})")
        return super().__getitem__(key)

    def names(self) -> List[str]:
        return [f.name for f in self]

    def _repr_html_(self) -> str:
        return "".join(f._repr_html_() for f in self)


def _figures_in(paths) -> Figures:
    out = Figures()
    for p in map(Path, paths):
        if p.suffix in _FIGURE_SUFFIXES:
            out.append(Figure(p.stem, p.suffix, p.read_bytes()))
    return out


class Result:
    """The outcome of :func:`run`.

    Attributes (numpy arrays, one row per step from ``t = 0``):

    * ``t`` (steps+1,); ``u``, ``v``, ``a`` (steps+1, n_dofs): relative displacement, velocity,
      acceleration;
    * ``coupling_force``, ``error_force``, ``compensation_force``, ``measured_displacement``
      (steps+1, n_coupling) for substructure tests, else None;
    * ``reference`` (steps+1, n_dofs): the monolithic reference's displacements, or None;
    * ``history``: every column of ``history.csv`` (a :class:`Table`);
    * ``substeps``: the sub-step records (``substeps.csv``: step, substep, t, cmd, fm, dm, ...)
      or None for a monolithic run;
    * ``response``: the engineering rows (``response.csv``) or None;
    * ``summary``: the dict of ``summary.json`` (its ``outputs`` is empty until :meth:`save`);
    * ``completed``, ``error``: whether the run completed, and the one-line reason if not.
    """

    def __init__(self, raw: Dict[str, Any]) -> None:
        self.summary: Dict[str, Any] = json.loads(raw["summary"])
        self.history: Table = _table(raw["history"])
        self.substeps: Optional[Table] = _table(raw["substeps"])
        self.response: Optional[Table] = _table(raw["response"])
        self.error: Optional[str] = raw["error"]
        #: The files a run with ``out_dir`` wrote (``summary.json`` last; empty otherwise).
        self.outputs: List[str] = list(raw.get("outputs") or [])
        h = self.history
        self.t = h["t"]
        self.u = h.group("u")
        self.v = h.group("v")
        self.a = h.group("a")
        sub = "fc1" in h.names
        self.coupling_force = h.group("fc") if sub else None
        self.error_force = h.group("fe") if sub else None
        self.compensation_force = h.group("fu") if sub else None
        self.measured_displacement = h.group("dm") if sub else None
        self.reference = h.group("uref") if "uref1" in h.names else None
        # (kind, text, name, base_dir) of the config, for plot()
        self._source: Optional[Tuple[str, str, str, str]] = None
        self._realtime = self.summary.get("mode") == "realtime"

    def plot(self, format: str = "png") -> "Figures":
        """The figures ``substep run`` draws for this test (the same files, byte for byte:
        displacement, acceleration, coupling force, error force, hysteresis, reference,
        energy, ground motion, ... as ``[output.plots] figures`` chooses), as
        :class:`Figure` objects that Jupyter shows inline; ``figure.save(path)`` writes one.

        A run with ``out_dir`` and figures in that ``format`` already drew them: they are read
        from there. Otherwise the test is run again into a temporary folder (a run is
        deterministic: the same numbers to the bit) and drawn there. A real-time run draws no
        figures (nor does the CLI's); its ``history`` has the data.
        """
        if self._realtime:
            raise ConfigError("plot: a real-time run draws no figures (as substep run --realtime); "
                              "plot its history, or run it offline")
        if not isinstance(format, str) or format not in ("png", "svg", "pdf"):
            raise ConfigError(f"plot: format: {format!r} is not png, svg or pdf")
        drawn = [p for p in self.outputs if Path(p).suffix == "." + format and Path(p).exists()]
        if drawn:
            return _figures_in(drawn)
        if self._source is None:
            raise ConfigError("plot: this Result does not come from substep.run")
        import shutil
        import tempfile

        tmp = tempfile.mkdtemp(prefix="substep-plot-")
        try:
            kind, text, name, base_dir = self._source
            raw = _substep.run_folder(kind, text, name, base_dir, tmp, True, format, "csv", "{}")
            return _figures_in(raw["outputs"])
        finally:
            shutil.rmtree(tmp, ignore_errors=True)

    @property
    def completed(self) -> bool:
        return bool(self.summary.get("completed"))

    def to_pandas(self):
        """The history as a ``pandas.DataFrame``, columns named as in ``history.csv``."""
        return self.history.to_pandas()

    def save(self, path: Union[str, "os.PathLike[str]"]) -> List[str]:
        """Write the results; the format follows ``path``:

        * a directory (an existing one, or a path without suffix): ``history.csv``,
          ``substeps.csv``, ``response.csv`` and ``summary.json`` in it, byte for byte as
          ``substep run`` writes them (timings aside);
        * ``*.csv``: the history alone;
        * ``*.h5`` / ``*.hdf5``: HDF5;
        * ``*.mat``: a MATLAB level-5 MAT-file (every build; ``scipy.io.loadmat`` and MATLAB's
          ``load`` read it; see docs/python.md).

        Returns the paths written. A path that cannot be written raises :class:`ConfigError`
        (also an ``OSError``) naming it.
        """
        try:
            return self._save(path)
        except ConfigError:
            raise
        except OSError as e:
            reason = e.strerror or str(e)
            where = e.filename or os.fspath(path)
            raise _WriteError(f"{os.fspath(path)}: cannot write {where}: {reason}") from e

    def _save(self, path: Union[str, "os.PathLike[str]"]) -> List[str]:
        p = Path(path)
        suffix = p.suffix.lower()
        if suffix == ".csv":
            _substep.write_csv(str(p), self.history.names, np.ascontiguousarray(self.history.values))
            return [str(p)]
        if suffix in (".h5", ".hdf5", ".mat"):
            return _save_binary(self, p, suffix)
        if suffix and not p.is_dir():
            raise ConfigError(f"{p}: unknown output format {suffix!r} (use a directory, .csv, .h5, .hdf5 or .mat)")
        p.mkdir(parents=True, exist_ok=True)
        written = []
        for name, table in (("history.csv", self.history), ("substeps.csv", self.substeps),
                            ("response.csv", self.response)):
            if table is not None:
                out = p / name
                _substep.write_csv(str(out), table.names, np.ascontiguousarray(table.values))
                written.append(str(out))
        summary = dict(self.summary)
        summary["outputs"] = written + [str(p / "summary.json")]
        (p / "summary.json").write_text(json.dumps(summary, indent=2, ensure_ascii=False) + "\n")
        written.append(str(p / "summary.json"))
        return written

    def __repr__(self) -> str:
        s = self.summary
        state = "completed" if self.completed else f"stopped: {self.error}"
        return f"<substep.Result {s.get('config')}: {s.get('steps_done')} of {s.get('steps')} steps, {state}>"


def _save_binary(result: Result, path: Path, suffix: str) -> List[str]:
    """``results.h5`` / ``results.mat`` (level 5) of the CLI (the same layout, docs/python.md
    "HDF5 / MATLAB"), from the tables written as CSV into a temporary folder beside ``path``."""
    import shutil
    import tempfile

    fmt = "mat" if suffix == ".mat" else "hdf5"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".substep-", dir=path.parent))
    try:
        result.save(tmp)
        written = _substep.write_container(str(tmp), fmt, (tmp / "summary.json").read_text(),
                                           getattr(result, "config_text", "") or "")
        os.replace(written, path)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return [str(path)]


class _WriteError(ConfigError, OSError):
    """A results path that cannot be written: a :class:`ConfigError` and an ``OSError``."""


class _ConfigTypeError(ConfigError, TypeError):
    """A config or value of the wrong Python type: a :class:`ConfigError` and a ``TypeError``."""


def _plain(value, path: str = ""):
    """`value` (a config dict or one of its values) as plain TOML values: numpy scalars and
    arrays become numbers and lists; anything else that TOML cannot hold raises
    :class:`ConfigError` naming its key path."""
    if isinstance(value, Mapping):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise _ConfigTypeError(f"<dict>: {path or '(top level)'}: the key {k!r} is not a string")
            out[k] = _plain(v, f"{path}.{k}" if path else k)
        return out
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v, f"{path}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(f"<dict>: {path}: {value} is not a finite number")
    if isinstance(value, (str, bool, int, float)):
        return value
    raise _ConfigTypeError(
        f"<dict>: {path}: a {type(value).__name__} is not a config value (use numbers, strings, booleans, "
        "lists and dicts)"
    )


def _config_source(config: ConfigLike) -> Tuple[str, str, str]:
    """(kind, text, name) of a config given as a path, TOML text or dict."""
    if isinstance(config, Mapping):
        return "json", json.dumps(_plain(config), allow_nan=True), "<dict>"
    if isinstance(config, os.PathLike):
        return "path", os.fspath(config), os.fspath(config)
    if isinstance(config, str):
        if "\n" in config or ("=" in config and not os.path.exists(config)):
            return "toml", config, "<string>"
        return "path", config, config
    raise _ConfigTypeError(f"config: must be a path, a TOML string or a dict, not {type(config).__name__}")


_LIVE_KEYS = {
    "monitor": (str,),
    "monitor_public": (bool,),
    "monitor_token": (str,),
    "monitor_linger": (int, float),
    "stability": (str,),
    "pace": (int, float),
}
_REALTIME_KEYS = {
    "max_missed": (int, float),
    "late_policy": (str,),
    "lock_memory": (bool,),
    "fifo_priority": (int,),
}


def _options(values: Dict[str, Any], kinds: Dict[str, tuple]) -> Dict[str, Any]:
    out = {}
    for key, value in values.items():
        if value is None:
            continue
        allowed = kinds[key]
        if isinstance(value, bool) and bool not in allowed or not isinstance(value, allowed):
            names = " or ".join(k.__name__ for k in allowed)
            raise _ConfigTypeError(f"{key}: must be a {names}, not {type(value).__name__}")
        out[key] = value
    return out


def _read_table(path: Path):
    """(names, columns × rows) of a CSV table written by a run."""
    with open(path, newline="") as f:
        names = f.readline().strip().split(",")
    values = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    if values.size == 0:
        values = np.zeros((0, len(names)))
    return names, np.ascontiguousarray(values.T)


def run(
    config: ConfigLike,
    *,
    out_dir: Optional[Union[str, os.PathLike]] = None,
    plots: Optional[bool] = None,
    plot_format: Optional[str] = None,
    format: Optional[str] = None,
    realtime: bool = False,
    monitor: Optional[str] = None,
    monitor_token: Optional[str] = None,
    monitor_public: bool = False,
    monitor_linger: Optional[float] = None,
    stability: Optional[str] = None,
    pace: Optional[float] = None,
    max_missed: Optional[float] = None,
    late_policy: Optional[str] = None,
    lock_memory: bool = False,
    fifo_priority: Optional[int] = None,
    raise_on_stop: bool = True,
) -> Result:
    """Run a test definition and return its histories and summary.

    ``config`` is a path to a TOML test definition (``docs/config.md``), the TOML text itself,
    or a dict with the same structure (``{"structure": {"sdof": {...}}, ...}``). Relative paths
    inside a TOML string or dict start at the current directory; inside a file, at its folder.
    A lab target (``[substructure.lab]``) or a remote site (``[substructure.remote]``) in the
    definition is driven exactly as by the CLI.

    With ``out_dir``, the run also writes its output folder exactly as
    ``substep run CONFIG --out OUT_DIR`` does (the same files, the same bytes in every CSV
    table and figure, ``summary.json``; ``Result.outputs`` lists them). ``plots`` (default: the
    config's ``[output] plots``), ``plot_format`` (``"png"``, ``"svg"`` or ``"pdf"``, default:
    ``[output.plots] format``) and ``format`` (``"csv"``, ``"hdf5"`` or ``"mat"``, default:
    ``[output] format``) are the CLI's ``--no-plots``, ``--plot-format`` and ``--format``.

    ``realtime=True`` is ``substep run --realtime`` (docs/realtime.md): the test against the
    wall clock, into ``out_dir`` (default: the config's ``[output] dir``, else ``results``), with
    ``max_missed``, ``late_policy``, ``lock_memory`` and ``fifo_priority`` as the CLI's flags; a
    run that missed more deadlines than allowed raises :class:`RunError` ("not real time").

    ``monitor="127.0.0.1:8080"`` (``""``: the config's ``[monitor] address``) serves the live
    page during the run (docs/monitor.md) and prints its address and token;
    ``monitor_token``, ``monitor_public``, ``monitor_linger`` (seconds the page stays after the
    run, default 30), ``stability`` (``"warn"``, ``"stop"`` or ``"off"``) and ``pace`` are the
    CLI's ``--monitor-*``, ``--stability`` and ``--pace``.

    Returns a :class:`Result` (numpy arrays ``t``, ``u``, ``v``, ``a``, ``coupling_force``,
    ``error_force``, ``measured_displacement``, ``reference``, ``substeps``; ``summary``, the
    dict of ``summary.json``; ``to_pandas()``; ``save(path)``).

    Raises :class:`ConfigError` for bad input (the CLI's one-line message, its exit code 2) and
    :class:`RunError` for a run that diverged or stopped (a safety limit, a failing site; the
    CLI's exit code 1) unless ``raise_on_stop=False``; the exception's ``result`` attribute has
    the steps done. The GIL is released while the test runs; offline, Ctrl-C stops it between
    two steps and raises ``KeyboardInterrupt``.
    """
    kind, text, name = _config_source(config)
    for key, value, kinds in (("plots", plots, bool), ("plot_format", plot_format, str), ("format", format, str),
                              ("realtime", realtime, bool)):
        if value is not None and not isinstance(value, kinds):
            raise _ConfigTypeError(f"{key}: must be a {kinds.__name__}, not {type(value).__name__}")
    if out_dir is not None and not isinstance(out_dir, (str, os.PathLike)):
        raise _ConfigTypeError(f"out_dir: must be a path, not {type(out_dir).__name__}")
    live = _options(
        {"monitor": monitor, "monitor_token": monitor_token, "monitor_public": monitor_public or None,
         "monitor_linger": monitor_linger, "stability": stability, "pace": pace},
        _LIVE_KEYS,
    )
    rt = _options(
        {"max_missed": max_missed, "late_policy": late_policy, "lock_memory": lock_memory or None,
         "fifo_priority": fifo_priority},
        _REALTIME_KEYS,
    )
    if rt and not realtime:
        raise ConfigError(f"{', '.join(rt)}: options of a real-time run; give realtime=True too")
    if realtime:
        if pace is not None:
            raise ConfigError("pace: paces an offline run; a real-time run keeps the wall clock")
        if plots is not None or plot_format is not None or format is not None:
            raise ConfigError("plots, plot_format, format: a real-time run writes no figures or containers")
        raw = _substep.run_realtime(kind, text, name, os.getcwd(), None if out_dir is None else os.fspath(out_dir),
                                    json.dumps({**rt, **live}))
        folder = Path(raw["out_dir"])
        raw["history"] = _read_table(folder / "history.csv")
        raw["substeps"] = _read_table(folder / "substeps.csv") if (folder / "substeps.csv").exists() else None
        raw["response"] = None
    elif out_dir is None:
        if plots is not None or plot_format is not None or format is not None:
            raise ConfigError("plots, plot_format, format: they choose what goes into out_dir; give out_dir too")
        raw = _substep.run(kind, text, name, os.getcwd(), json.dumps(live))
    else:
        raw = _substep.run_folder(kind, text, name, os.getcwd(), os.fspath(out_dir), plots, plot_format, format,
                                  json.dumps(live))
    result = Result(raw)
    result._source = (kind, text, name, os.getcwd())
    if raw["error"] is not None and raise_on_stop:
        cls = RunError if raw["error_kind"] == "run" else ConfigError
        err = cls(raw["error"])
        err.result = result
        raise err
    return result


from . import analyze, benchmark  # noqa: E402  (they use run's helpers)


from .study import study  # noqa: E402  (needs _config_source above)
