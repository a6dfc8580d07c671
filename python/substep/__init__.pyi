import os
from typing import Any, Dict, List, Mapping, Optional, Union

import numpy as np
import pandas

from . import analyze as analyze
from . import benchmark as benchmark

ConfigLike = Union[str, os.PathLike[str], Mapping[str, Any]]

class ConfigError(Exception):
    """Bad input (the CLI's exit code 2); the message is the CLI's one-line error."""

class RunError(Exception):
    """A run that diverged or stopped (the CLI's exit code 1); `result` has the steps done."""
    result: "Result"

class Table:
    names: List[str]
    values: np.ndarray
    def __init__(self, names: List[str], values: np.ndarray) -> None: ...
    def __getitem__(self, name: str) -> np.ndarray: ...
    def __len__(self) -> int: ...
    def group(self, prefix: str) -> np.ndarray: ...
    def to_pandas(self) -> pandas.DataFrame: ...

class Figure:
    name: str
    format: str
    data: bytes
    def save(self, path: Union[str, os.PathLike[str]]) -> str: ...

class Figures(List[Figure]):
    def names(self) -> List[str]: ...

class Result:
    summary: Dict[str, Any]
    history: Table
    substeps: Optional[Table]
    outputs: List[str]
    def plot(self, format: str = "png") -> Figures: ...
    response: Optional[Table]
    error: Optional[str]
    t: np.ndarray
    u: np.ndarray
    v: np.ndarray
    a: np.ndarray
    coupling_force: Optional[np.ndarray]
    error_force: Optional[np.ndarray]
    compensation_force: Optional[np.ndarray]
    measured_displacement: Optional[np.ndarray]
    reference: Optional[np.ndarray]
    @property
    def completed(self) -> bool: ...
    def to_pandas(self) -> pandas.DataFrame: ...
    def save(self, path: Union[str, os.PathLike[str]]) -> List[str]: ...

def run(
    config: ConfigLike,
    *,
    out_dir: Optional[Union[str, os.PathLike[str]]] = None,
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
    """Run a test definition (path, TOML text or dict) and return its histories and summary;
    with ``out_dir``, also write the output folder ``substep run --out`` writes; ``realtime=True``
    runs against the wall clock; ``monitor=ADDR`` serves the live page."""

def study(
    base: ConfigLike,
    grid: Optional[Mapping[str, Any]] = None,
    samples: Optional[Mapping[str, Any]] = None,
    seeds: Optional[List[int]] = None,
    metrics: Optional[List[Any]] = None,
    client: Any = None,
    *,
    seed_key: Optional[str] = None,
    threads: int = 0,
    batch_size: Optional[int] = None,
) -> pandas.DataFrame: ...
