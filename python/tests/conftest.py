"""Shared fixtures: the repository root and the `substep` binary built by cargo (the CLI the
Python results are compared with)."""

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def cli() -> Path:
    path = Path(os.environ.get("SUBSTEP_BIN", ROOT / "target" / "release" / "substep"))
    if not path.exists():
        pytest.fail(f"{path}: the substep binary is missing (cargo build --release)")
    return path


def run_cli(cli: Path, *args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    """The CLI with `args`, bounded in time, output captured as text."""
    return subprocess.run([str(cli), *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def read_csv_exact(path) -> "pandas.DataFrame":
    """A CSV file of numbers as a float DataFrame, each field parsed by Python's correctly
    rounded `float` (independent of the pandas version's parser)."""
    import csv

    import pandas as pd

    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    return pd.DataFrame([[float(x) for x in r] for r in body], columns=header, dtype=float)
